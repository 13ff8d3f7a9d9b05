// The jog pendant: hold-to-move buttons over DeviceService.Jog. Holding a button is the
// deadman: while it is held the page sends a JogRequest every period; letting go (or leaving the
// button, or the page losing focus) sends deadman=false and ends the stream. The backend
// forwards these messages, so the device's own deadman timeout stops the arm if they stop coming.
// Each press is a stream of its own with a fresh id (the link's ids only grow): once a press's
// stream has ended (released, the deadman, an abort), the backend drops any message of it still
// on its way, so nothing moves until the button is pressed again.
const $ = (id) => document.getElementById(id);
const JOG = 'landscape.v1.DeviceService/Jog';
const PERIOD_MS = 50;
const AXES = {
  REFERENCE_FRAME_JOINT_FRAME: ['J1', 'J2', 'J3', 'J4', 'J5', 'J6'],
  cartesian: ['X', 'Y', 'Z', 'Rx', 'Ry', 'Rz'],
};

export class JogPendant {
  constructor(ctx) {
    this.ctx = ctx;
    this.active = null;     // {stream, timer}
    $('jog-frame').addEventListener('change', () => this.build());
    $('manual-control').addEventListener('change', (e) => ctx.command('ManualControl', {
      type: e.target.checked ? 'MANUAL_CONTROL_TYPE_TEACHPENDANT' : 'MANUAL_CONTROL_TYPE_OFF',
    }).then((reply) => { if (!reply) e.target.checked = !e.target.checked; }));
    window.addEventListener('blur', () => this.release());
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
        button.addEventListener('pointerdown', (event) => { event.preventDefault(); this.hold(frame, axis, sign); });
        for (const end of ['pointerup', 'pointerleave', 'pointercancel']) button.addEventListener(end, () => this.release());
        box.append(button);
      }
    });
    this.ctx.changed('jog');   // the new buttons follow the lock like the others
  }

  hold(frame, axis, sign) {
    this.release();
    const velocity = [0, 0, 0, 0, 0, 0];
    velocity[axis] = sign * Number($('jog-speed').value);
    const stream = this.ctx.link.open(this.ctx.device, JOG, (reply) => {
      if (!reply.status) return;
      if (this.active?.stream === stream) this.active.ended = true;   // nothing more to send
      if (reply.status.code) this.ctx.refused('Jog', reply.status);
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
