// What the page knows of one device and how it calls it: the link, the device's latest
// messages (the model), who is signed in, the page's own session and lock on it, and
// `command`, which calls an RPC and shows a refusal as the server gave it.
import { Refused } from './link.js';
import { SI } from './units.js';

export const DEVICE = 'landscape.v1.DeviceService/';

export class DeviceContext {
  constructor(link, device, log, person, refusals) {
    this.link = link;
    this.device = device;
    this.log = log;
    this.person = person;        // {name, role} of who is signed in
    this.refusals = refusals;    // shows a refusal to the person (refusal.js)
    this.lastStateReason = '';   // the newest state change's reason (the event stream's)
    this.lastSequence = 0;       // the newest event's sequence number
    this.model = {
      started: null,        // StreamStarted: the stream's rate, frame, units, note
      sample: null,         // the newest StateSample
      status: {},           // "GetDeviceState" -> its newest reply (or {refused: Status})
      units: SI,            // the device's units (GetUnits), for display and for commands
      cell: null,           // GetCellDescription's reply (or {refused: Status})
      robotType: '',
    };
    this.session = null;    // {stream, sessionId} of the page's open session
    this.holdsLock = false;
    this.listeners = [];
  }

  onChange(listener) { this.listeners.push(listener); }

  changed(what) { for (const listener of this.listeners) listener(what); }

  // A unary (or client-streaming: streamed) call of `rpc` ("Activate" or a full name). Resolves
  // with the reply, or with null after showing the refusal.
  async command(rpc, request = {}, options = {}) {
    const name = rpc.includes('/') ? rpc : DEVICE + rpc;
    try {
      return await this.link.call(this.device, name, request, options);
    } catch (error) {
      if (!(error instanceof Refused)) throw error;
      this.refused(name.split('/').pop(), error.status);
      return null;
    }
  }

  refused(what, status) {
    this.refusals.show(this.device, what, status);
  }

  // The device's state as the newest sample or GetDeviceState says.
  get deviceState() {
    return this.model.sample?.deviceState || this.model.status.GetDeviceState?.state || '';
  }

  get locked() { return Boolean(this.model.status.GetDeviceState?.locked); }
}
