// The control panel of the selected device: the page's session and lock, power, reset, the
// e-stop's release, the speed override, acceleration and units. The speed slider shows the
// device's own value (GetVelocities) whenever nobody is moving it, so it never claims a speed
// the arm does not run at; moving it sets the speed when let go.
import { fmt } from './units.js';
import { UNIT_WORDS } from './words.js';

const $ = (id) => document.getElementById(id);
const EXPECT_MS = 3000;   // longer than the status reads' period (device_hub.py: 0.5 s)

export class Controls {
  constructor(selection) {
    this.selection = selection;
    const session = () => selection.device.session;
    const command = (rpc, request) => selection.ctx.command(rpc, request);
    const on = (id, handler) => $(id).addEventListener('click', handler);
    on('btn-session', () => session().open());
    on('btn-session-close', () => session().close());
    on('btn-lock', () => session().lock());
    on('btn-release', () => session().release());
    on('btn-activate', () => command('Activate'));
    on('btn-deactivate', () => command('Deactivate'));
    on('btn-reset', () => command('Reset'));
    on('btn-estop-release', () => command('OperatePanel', { action: 'PANEL_ACTION_RELEASE_ESTOP' }));
    on('btn-accel', () => command('SetAcceleration', { accel: Number($('accel').value), attribute: 'ACCEL_TYPE_PERCENT_ACCEL' }));
    on('btn-units', () => command('SetUnits', { linearUnits: $('units-linear').value, angularUnits: $('units-angular').value }));
    for (const select of [$('units-linear'), $('units-angular')]) {
      for (const option of select.options) option.textContent = UNIT_WORDS[option.value];
    }
    this.speed();
    selection.on((what, device) => {
      if (device === selection.device && ['switch', 'status'].includes(what)) this.showSpeed(what === 'switch');
    });
  }

  // The slider sets the speed when let go (or at each arrow key); the box takes an exact value.
  speed() {
    const slider = $('speed');
    const typed = $('speed-typed');
    this.moving = false;
    slider.addEventListener('input', () => { this.moving = true; typed.value = slider.value; });
    slider.addEventListener('change', () => this.setSpeed(Number(slider.value)));
    $('btn-speed').addEventListener('click', () => this.setSpeed(Number(typed.value)));
    typed.addEventListener('keydown', (event) => { if (event.key === 'Enter') this.setSpeed(Number(typed.value)); });
  }

  // Set: the slider stays at the new value until the device's next read says it (a refused
  // speed goes back to the device's at once).
  async setSpeed(percent) {
    const reply = await this.selection.ctx.command('SetSpeed', { speed: percent, attribute: 'SPEED_TYPE_PERCENT_SPEED' });
    this.expected = reply ? { percent, until: performance.now() + EXPECT_MS } : null;
    this.moving = false;
    this.showSpeed(!reply);
  }

  // The device's speed override on the slider and in the box when it changes (or `again`),
  // unless the person is moving the slider: what they type stays until the device's changes.
  showSpeed(again = false) {
    const velocities = this.selection.ctx.model.status.GetVelocities;
    const percent = velocities && !velocities.refused ? velocities.percentVelocity : null;
    $('speed-device').textContent = percent === null ? 'device: –' : `device: ${fmt(percent, 0)} %`;
    if (percent === null || this.moving) return;
    const expected = this.expected;
    if (expected && percent !== expected.percent && performance.now() < expected.until) return;
    this.expected = null;
    if (percent === this.shown && !again) return;
    this.shown = percent;
    $('speed').value = percent;
    $('speed-typed').value = fmt(percent, 0);
  }
}
