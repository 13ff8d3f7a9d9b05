// The page's WebSocket to the dashboard backend. Every frame is one message of one landscape.v1
// RPC of one device, in protobuf's canonical JSON (see supervisor_gui_web/wire.py):
//   in:  {device, rpc, id?, reply?: Any, status?: google.rpc.Status}
//   out: {device, rpc, id, request? | requests? | cancel?}

export class Refused extends Error {
  // A call the device server (or the backend on its behalf) refused: status is google.rpc.Status.
  constructor(rpc, status) {
    super(status.message);
    this.rpc = rpc;
    this.status = status;
  }
}

// The backend closes a page's socket with this code when the person's sign-in ended.
export const CLOSE_SIGNED_OUT = 4001;

export class Link {
  constructor(url) {
    this.url = url;
    this.nextId = 1;               // call ids only grow: a jog press's id is newer than all before
    this.pending = new Map();      // id -> {resolve, reject} of a unary call
    this.streams = new Map();      // id -> handler(frame) of a stream the page opened
    this.feedHandlers = [];        // handler(frame) for frames that answer no call of ours
    this.connectionHandlers = [];  // handler(up, closeEvent?) when the socket opens or closes
    this.onSignedOut = () => {};   // (why): the sign-in ended; no reconnecting
    this.mayReconnect = async () => true;
    this.up = false;               // the socket is open
    this.connect();
  }

  connect() {
    this.ws = new WebSocket(this.url);
    this.ws.onopen = () => {
      this.up = true;
      this.connectionHandlers.forEach((handler) => handler(true));
    };
    this.ws.onclose = (event) => {
      this.up = false;
      const signedOut = event.code === CLOSE_SIGNED_OUT;
      const why = signedOut ? `signed out: ${event.reason}`
        : `connection to the supervisor lost (WebSocket closed, code ${event.code})`;
      const lost = { code: 14, message: why, details: [] };
      this.connectionHandlers.forEach((handler) => handler(false, event));
      for (const [, call] of this.pending) call.reject(new Refused('', lost));
      this.pending.clear();
      for (const [id, handler] of this.streams) handler({ id, status: lost });
      this.streams.clear();
      if (signedOut) { this.onSignedOut(event.reason); return; }
      setTimeout(async () => { if (await this.mayReconnect()) this.connect(); }, 1000);
    };
    this.ws.onmessage = (event) => this.dispatch(JSON.parse(event.data));
  }

  dispatch(frame) {
    if (frame.id !== undefined && this.pending.has(frame.id)) {
      const call = this.pending.get(frame.id);
      this.pending.delete(frame.id);
      if (frame.status && frame.status.code) call.reject(new Refused(frame.rpc, frame.status));
      else call.resolve(frame.reply);
    } else if (frame.id !== undefined && this.streams.has(frame.id)) {
      this.streams.get(frame.id)(frame);
      if (frame.status) this.streams.delete(frame.id);
    } else {
      for (const handler of this.feedHandlers) handler(frame);
    }
  }

  onFeed(handler) { this.feedHandlers.push(handler); }

  onConnection(handler) { this.connectionHandlers.push(handler); }

  send(body) {
    if (this.ws.readyState !== WebSocket.OPEN) return false;
    this.ws.send(JSON.stringify(body));
    return true;
  }

  // A unary or client-streaming call: resolves with the reply (an Any's JSON), rejects with Refused.
  call(device, rpc, request = {}, { streamed = false } = {}) {
    const id = this.nextId++;
    return new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject });
      const body = streamed ? { device, rpc, id, requests: request } : { device, rpc, id, request };
      if (!this.send(body)) {
        this.pending.delete(id);
        reject(new Refused(rpc, { code: 14, message: 'not connected to the dashboard', details: [] }));
      }
    });
  }

  // A server-streaming call (GetPath): resolves with its replies once it ended, rejects with
  // Refused.
  collect(device, rpc, request = {}) {
    return new Promise((resolve, reject) => {
      const replies = [];
      const stream = this.open(device, rpc, (frame) => {
        if (frame.reply) replies.push(frame.reply);
        if (!frame.status) return;
        if (frame.status.code) reject(new Refused(rpc, frame.status));
        else resolve(replies);
      });
      if (!stream.send(request)) {
        this.streams.delete(stream.id);
        reject(new Refused(rpc, { code: 14, message: 'not connected to the dashboard', details: [] }));
      }
    });
  }

  // A stream the page opens (the session, a jog): returns {id, send(request), cancel()}; every
  // frame of it, replies and the final status, goes to handler.
  open(device, rpc, handler) {
    const id = this.nextId++;
    this.streams.set(id, handler);
    return {
      id,
      send: (request) => this.send({ device, rpc, id, request }),
      cancel: () => this.send({ device, rpc, id, cancel: true }),
    };
  }
}

// The message type of an Any's JSON, e.g. "landscape.v1.StateSample".
export function typeOf(any) {
  return any && any['@type'] ? any['@type'].split('/').pop() : '';
}
