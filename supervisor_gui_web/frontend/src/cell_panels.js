// Tools (get, put, open, close), the digital I/O panel (bits by name, outputs toggled) and sensor
// readings of the selected device. Each is a plain call of the contract; a device that has not
// built one answers UNIMPLEMENTED, and the page says so as for any refusal.
const $ = (id) => document.getElementById(id);
const DIO = 'landscape.v1.DigitalIOService/';
const IO_PERIOD_MS = 500;
const MAIN_FUNCTION = 1;   // bit 0: the tool's main function (close the gripper, vacuum on)

export class ToolPanel {
  constructor(selection) {
    const tool = () => $('tool-id').value;
    const on = (id, handler) => $(id).addEventListener('click', handler);
    const command = (rpc, request) => selection.ctx.command(rpc, request);
    on('btn-tool-get', () => command('GetTool', { toolId: tool() }));
    on('btn-tool-put', () => command('PutTool', { toolId: tool() }));
    on('btn-tool-close', () => command('ActivateTool', { toolId: tool(), bitField: MAIN_FUNCTION }));
    on('btn-tool-open', () => command('DeactivateTool', { toolId: tool(), bitField: MAIN_FUNCTION }));
    selection.on((what, device) => {
      const cell = device.ctx.model.cell;
      if (device !== selection.device || !['switch', 'cell'].includes(what)) return;
      this.setTools(cell && !cell.refused ? cell.bodies.filter((b) => b.kind === 'KIND_TOOL').map((b) => b.name) : []);
    });
  }

  // The cell's tools, from its description; the one chosen stays chosen.
  setTools(names) {
    const select = $('tool-id');
    const chosen = select.value;
    if ([...select.options].map((o) => o.value).join() === names.join()) return;
    select.replaceChildren(...names.map((name) => new Option(name, name)));
    if (names.includes(chosen)) select.value = chosen;
  }
}

export class IoPanel {
  constructor(selection) {
    this.selection = selection;
    this.units = [];
    $('btn-io-list').addEventListener('click', () => this.list());
    selection.on((what) => {
      if (what !== 'switch') return;
      clearInterval(this.timer);
      this.units = [];
      $('io').replaceChildren();
    });
  }

  get ctx() { return this.selection.ctx; }

  async list() {
    clearInterval(this.timer);
    const reply = await this.ctx.command(DIO + 'ListDigitalIO');
    const box = $('io');
    box.replaceChildren();
    if (!reply) { box.textContent = 'the device did not give its I/O map (see the refusal)'; return; }
    this.units = reply.units;
    for (const unit of this.units) {
      const row = document.createElement('div');
      row.className = 'io-unit';
      const name = document.createElement('strong');
      name.textContent = unit.name;
      row.append(name, ` (${unit.type} ${unit.unitId}) `);
      for (const bit of unit.bits) {
        const element = document.createElement(unit.type === 'output' ? 'button' : 'span');
        element.className = 'bit';
        element.textContent = bit.name;
        element.dataset.unit = unit.unitId;
        element.dataset.bit = bit.bit;
        if (unit.type === 'output') {
          element.dataset.needs = 'lock';
          element.addEventListener('click', () => this.toggle(unit, bit, element));
        }
        row.append(element);
      }
      box.append(row);
    }
    this.timer = setInterval(() => this.read(), IO_PERIOD_MS);
  }

  async read() {
    const ctx = this.ctx;
    for (const unit of this.units) {
      let reply;
      try {
        reply = await ctx.link.call(ctx.device, DIO + 'GetDigitalIO', { type: unit.type, unitId: unit.unitId });
      } catch (refused) {
        clearInterval(this.timer);
        ctx.refused('GetDigitalIO', refused.status);
        return;
      }
      if (ctx !== this.ctx) return;   // another device was chosen meanwhile
      for (const element of document.querySelectorAll(`#io .bit[data-unit="${unit.unitId}"]`)) {
        element.classList.toggle('on', Boolean(reply.bitsOn & (1 << Number(element.dataset.bit))));
      }
    }
  }

  toggle(unit, bit, element) {
    const mask = 1 << bit.bit;
    const on = element.classList.contains('on');
    return this.ctx.command(DIO + 'SetDigitalIO', {
      type: 'output', unitId: unit.unitId, bitsOn: on ? 0 : mask, bitsOff: on ? mask : 0,
      description: `dashboard: ${bit.name} ${on ? 'off' : 'on'}`,
    });
  }
}

export class SensorPanel {
  constructor(selection) {
    const show = async (sensorType) => {
      const reply = await selection.ctx.command('GetSensorReading', { sensorType });
      if (reply) $('sensors').textContent = `${sensorType}: ${reply.currentData.map((v) => v.toFixed(4)).join(', ')}`;
    };
    $('btn-read-force').addEventListener('click', () => show('force_sensor'));
    $('btn-read-laser').addEventListener('click', () => show('laser_standoff_sensor'));
  }
}
