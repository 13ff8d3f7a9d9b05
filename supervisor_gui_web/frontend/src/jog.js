// The jog pendant of the selected device: hold-to-move buttons over DeviceService.Jog. Holding
// a button (the pointer, or Space or Enter on the focused button) is the deadman: while it is
// held the page sends a JogRequest every period; letting go (or leaving the button, the
// button losing focus, the page losing focus, another device chosen) sends deadman=false and
// ends the stream. The backend forwards these messages, so the device's own deadman timeout
// stops the arm if they stop coming. Each press is a stream of its own with a fresh id (the
// link's ids only grow): once a press's stream has ended (released, the deadman, an abort),
// the backend drops any message of it still on its way, so nothing moves until the button is
// pressed again.
const $ = (id) => document.getElementById(id);
const JOG = 'landscape.v1.DeviceService/Jog';
const PERIOD_MS = 50;
const AXES = {
  REFERENCE_FRAME_JOINT_FRAME: ['J1', 'J2', 'J3', 'J4', 'J5', 'J6'],
  cartesian: ['X', 'Y', 'Z', 'Rx', 'Ry', 'Rz'],
};
const KEYS = new Set([' ', 'Enter']);

export class JogPendant {
  constructor(selection) {
    this.selection = selection;
    this.active = null;     // {ctx, stream, frame, timer, ended}
    $('jog-frame').addEventListener('change', () => this.build());
    $('manual-control').addEventListener('change', (e) => selection.ctx.command('ManualControl', {
      type: e.target.checked ? 'MANUAL_CONTROL_TYPE_TEACHPENDANT' : 'MANUAL_CONTROL_TYPE_OFF',
    }).then((reply) => { if (!reply) e.target.checked = !e.target.checked; }));
    window.addEventListener('blur', () => this.release());
    selection.on((what, device) => {
      if (what === 'switch') this.release();
      if (device === selection.device && ['switch', 'status'].includes(what)) {
        const manual = selection.ctx.model.status.GetDeviceState?.manualControl;
        $('manual-control').checked = manual === 'teachpendant';
      }
    });
    this.build();
  }

  build() {
    const frame = $('jog-frame').value;
    const names = AXES[frame] || AXES.cartesian;
    const box = $('jog-buttons');
    box.replaceChildren();
    names.forEach((name, axis) => {
      for (const sign of [-1, 1]) {
        const button = document.createElement('button');
        button.textContent = `${name}${sign < 0 ? '−' : '+'}`;
        button.dataset.needs = 'lock';
        button.dataset.testid = `jog-${name}${sign < 0 ? '-' : '+'}`;
        button.setAttribute('aria-label', `jog ${name} ${sign < 0 ? 'minus' : 'plus'} (hold)`);
        button.addEventListener('pointerdown', (event) => { event.preventDefault(); this.hold(frame, axis, sign); });
        for (const end of ['pointerup', 'pointerleave', 'pointercancel', 'blur']) button.addEventListener(end, () => this.release());
        button.addEventListener('keydown', (event) => {
          if (!KEYS.has(event.key)) return;
          event.preventDefault();   // no click, no scrolling
          if (!event.repeat) this.hold(frame, axis, sign);
        });
        button.addEventListener('keyup', (event) => { if (KEYS.has(event.key)) this.release(); });
        box.append(button);
      }
    });
  }

  hold(frame, axis, sign) {
    this.release();
    const ctx = this.selection.ctx;
    const velocity = [0, 0, 0, 0, 0, 0];
    velocity[axis] = sign * Number($('jog-speed').value);
    const stream = ctx.link.open(ctx.device, JOG, (reply) => {
      if (!reply.status) return;
      if (this.active?.stream === stream) this.active.ended = true;   // nothing more to send
      if (reply.status.code) ctx.refused('Jog', reply.status);
      this.release();
    });
    const send = () => stream.send({ deadman: true, frame, velocity });
    send();
    this.active = { stream, frame, timer: setInterval(send, PERIOD_MS) };
  }

  release() {
    if (!this.active) return;
    const { stream, frame, timer, ended } = this.active;
    this.active = null;
    clearInterval(timer);
    if (ended) return;
    stream.send({ deadman: false, frame, velocity: [0, 0, 0, 0, 0, 0] });
    stream.cancel();
  }
}
