// Which device the panels show and command (the status bar and the 3D view show them all),
// and the one place a panel hears of any device's change: listener(what, device), with
// what = 'switch' when another device is chosen.
export class Selection {
  constructor(devices) {
    this.devices = devices;            // name -> Device, in the supervisor's order
    this.device = devices.values().next().value;
    this.listeners = [];
    for (const device of devices.values()) device.ctx.onChange((what) => this.emit(what, device));
  }

  get ctx() { return this.device.ctx; }

  on(listener) { this.listeners.push(listener); }

  emit(what, device) { for (const listener of this.listeners) listener(what, device); }

  select(name) {
    const device = this.devices.get(name);
    if (!device || device === this.device) return;
    this.device = device;
    this.emit('switch', device);
  }
}
