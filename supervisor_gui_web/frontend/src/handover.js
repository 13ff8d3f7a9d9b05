// Control handed over between two people signed in to this supervisor
// (supervisor_gui_web/handover.py). The one asking opens a session and asks; the lock holder
// sees the request in a banner and hands the lock over or declines. Handing over powers the
// arm down and releases; the asker's session then holds the lock. Nothing takes a lock
// without its holder's word.
const $ = (id) => document.getElementById(id);

function button(text, handler) {
  const made = document.createElement('button');
  made.textContent = text;
  made.addEventListener('click', handler);
  return made;
}

// One device's requests, both ways: its banner for the holder, its line for the asker.
export class ControlRequests {
  constructor(device) {
    this.device = device;
    this.line = '';           // what the asker's panel says
    this.asking = false;      // this page asked and waits
    this.banner = document.createElement('div');
    this.banner.className = 'banner handover';
    this.banner.dataset.testid = `handover-${device.name}`;
    this.banner.setAttribute('role', 'alert');
    this.banner.hidden = true;
    document.getElementById('banners').append(this.banner);
  }

  call(name, request = {}) {
    return this.device.ctx.command(`supervisor/${name}`, request);
  }

  async ask() {
    if (!await this.device.session.open()) return;
    if (await this.call('RequestControl')) this.asking = true;
    this.device.ctx.changed('handover');
  }

  cancel() { return this.call('CancelControlRequest'); }

  // A supervisor/Control frame's reply.
  notice(body) {
    const [[what, detail]] = Object.entries(body);
    const name = this.device.name;
    if (what === 'asked') {
      this.prompt(`${detail.by} asks for control of ${name}.`, detail.expires_in_ms);
      return;
    }
    this.banner.hidden = true;
    if (what === 'waiting') this.say(`asked ${detail.holder} for control; waiting for an answer`, true);
    else if (what === 'declined') this.say(`${detail.by} declined to hand ${name} over`);
    else if (what === 'cancelled') this.say(`the request for ${name} was cancelled${detail.why ? `: ${detail.why}` : ''}`);
    else if (what === 'lapsed') this.say(`nobody answered the request for ${name} in ${detail.after_s} s`);
    else if (what === 'failed') this.say(detail.why);
    else if (what === 'given') {
      this.device.session.handedOver();
      this.say(`you handed ${name} over to ${detail.to}`);
    } else if (what === 'received') {
      this.device.session.locked();
      this.say(`${detail.from} handed ${name} over: you hold the lock (the arm is powered down)`);
    }
  }

  say(line, asking = false) {
    this.line = line;
    this.asking = asking;
    this.device.ctx.log.add('state', 0, `${this.device.name}: ${line}`);
    this.device.ctx.changed('handover');
  }

  // The holder's banner: hand over, or decline.
  prompt(text, expiresMs) {
    const until = new Date(Date.now() + expiresMs).toLocaleTimeString();
    const give = button('Hand over', () => this.device.session.lettingGo(
      () => this.call('AnswerControl', { give: true })));
    give.dataset.testid = `hand-over-${this.device.name}`;
    const decline = button('Decline', () => this.call('AnswerControl', { give: false }));
    decline.dataset.testid = `decline-${this.device.name}`;
    const words = document.createElement('span');
    words.textContent = `${text} Handing over powers the arm down and releases the lock to them (answer by ${until}). `;
    this.banner.replaceChildren(words, give, decline);
    this.banner.hidden = false;   // (no focus taken: a key meant for something else must not hand over)
  }
}

// The control panel's line: ask the holder, or cancel the request.
export class HandoverPanel {
  constructor(selection) {
    this.selection = selection;
    $('btn-request-control').addEventListener('click', () => selection.device.handover.ask());
    $('btn-cancel-request').addEventListener('click', () => selection.device.handover.cancel());
    selection.on((what, device) => {
      if (device === selection.device && ['switch', 'handover', 'lock', 'status'].includes(what)) this.show();
    });
  }

  show() {
    const { ctx, handover } = this.selection.device;
    const status = ctx.model.status.GetDeviceState;
    const other = status?.locked && !ctx.holdsLock;
    $('btn-request-control').hidden = !other || handover.asking;
    $('btn-cancel-request').hidden = !handover.asking;
    $('handover-status').textContent = handover.line;
  }
}
