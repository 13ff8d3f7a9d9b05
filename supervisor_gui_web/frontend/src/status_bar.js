// Always in view, one row per device, whatever is scrolled or folded: its state, who holds
// the lock, power, the e-stop (its state and a button that presses it), the alarms to
// acknowledge, the speed override and how fresh all this is. The device's name chooses it
// for the panels.
import { put } from './state_panel.js';
import { fmt } from './units.js';
import { motionWord, stateWord } from './words.js';

const ESTOP_PRESS = { action: 'PANEL_ACTION_PRESS_ESTOP' };
const REFRESH_MS = 250;
const FIELDS = ['state', 'lock', 'power', 'estop', 'alarms', 'speed', 'fresh'];

export class StatusBar {
  constructor(selection, onAlarms) {
    this.selection = selection;
    this.rows = new Map();
    const bar = document.getElementById('status');
    for (const device of selection.devices.values()) {
      const row = this.row(device, onAlarms);
      this.rows.set(device, row);
      bar.append(row.element);
      this.show(device);
    }
    selection.on((what, device) => {
      if (what === 'switch') this.rows.forEach((row, d) => row.name.setAttribute('aria-pressed', String(d === device)));
      else if (what !== 'sample' || device.ctx.deviceState !== this.rows.get(device).state) this.show(device);
    });
    // Samples, and the age of the newest, a few times a second.
    setInterval(() => this.rows.forEach((row, device) => this.show(device)), REFRESH_MS);
  }

  row(device, onAlarms) {
    const element = document.createElement('div');
    element.className = 'status-row';
    element.dataset.device = device.name;
    element.setAttribute('role', 'group');
    element.setAttribute('aria-label', `${device.name} at a glance`);
    const name = document.createElement('button');
    name.className = 'arm-name';
    name.textContent = device.name;
    name.title = `${device.name} (${device.target}): show its panels`;
    name.setAttribute('aria-pressed', String(device === this.selection.device));
    name.addEventListener('click', () => this.selection.select(device.name));
    const fields = {};
    element.append(name);
    for (const field of FIELDS) {
      fields[field] = document.createElement(field === 'alarms' ? 'button' : 'span');
      fields[field].className = `st-${field}`;
      fields[field].dataset.field = field;
      element.append(fields[field]);
      if (field === 'estop') element.append(this.estopButton(device));
    }
    fields.alarms.addEventListener('click', () => { this.selection.select(device.name); onAlarms(); });
    fields.fresh.setAttribute('role', 'status');
    return { element, name, fields, state: null };
  }

  // Anyone signed in may press it (the backend and the device allow every role), whoever holds
  // the lock: it is a button, reached with Tab and pressed with Enter or Space.
  estopButton(device) {
    const button = document.createElement('button');
    button.className = 'estop';
    button.id = `estop-${device.name}`;
    button.textContent = 'E-STOP';
    button.setAttribute('aria-label', `E-STOP ${device.name}: emergency stop`);
    button.addEventListener('click', () => device.ctx.command('OperatePanel', ESTOP_PRESS));
    return button;
  }

  show(device) {
    const { fields, element } = this.rows.get(device);
    const ctx = device.ctx;
    const sample = ctx.model.sample;
    const status = ctx.model.status.GetDeviceState;
    const state = ctx.deviceState;
    this.rows.get(device).state = state;
    put(fields.state, stateWord(state));
    fields.state.className = `st-state state-${stateWord(state)}`;
    const holder = status && !status.refused ? (status.locked ? status.lockHolder : 'nobody') : '?';
    put(fields.lock, `lock: ${holder}${ctx.holdsLock ? ' (you)' : ''}`);
    fields.lock.classList.toggle('mine', ctx.holdsLock);
    put(fields.power, `power ${sample ? motionWord(sample.controlMode) : '–'}`);
    const pressed = sample?.estop ?? status?.estop;
    put(fields.estop, pressed ? 'e-stop PRESSED' : 'e-stop released');
    fields.estop.classList.toggle('alert', Boolean(pressed));
    const count = device.alarms.unacknowledged;
    put(fields.alarms, `${count} alarm${count === 1 ? '' : 's'}`);
    fields.alarms.classList.toggle('alert', count > 0);
    fields.alarms.title = `${device.name}: alarms to acknowledge (show the list)`;
    const velocities = ctx.model.status.GetVelocities;
    put(fields.speed, `speed ${velocities && !velocities.refused ? fmt(velocities.percentVelocity, 0) : '–'} %`);
    const fresh = device.fresh;
    put(fields.fresh, fresh.stale ? `STALE ${fresh.describe().match(/\(([^)]*)\)/)?.[1] || ''}`.trim()
      : fresh.lastAt ? 'live' : 'waiting');
    fields.fresh.className = `st-fresh ${fresh.stale ? 'stale' : fresh.lastAt ? 'live' : ''}`;
    fields.fresh.title = fresh.describe();
    element.classList.toggle('stale', fresh.stale);
  }
}
