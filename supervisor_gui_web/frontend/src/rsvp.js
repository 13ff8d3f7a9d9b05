// An RSVP question of a device to this page's session (SessionService.Connect): a dialog with
// the device's choices and the countdown to its timeout, after which the device takes its
// default. The answer goes back on the session stream; the dialog closes when the event stream
// shows the exchange settled (answered here, in the alarm list, elsewhere, or timed out).
const $ = (id) => document.getElementById(id);

export class RsvpDialog {
  constructor() {
    this.dialog = $('rsvp');
    this.current = null;    // {rsvpId, timer}
    // Escape puts the question aside: it stays answerable in the alarm list until its time.
    this.dialog.addEventListener('cancel', () => this.close());
  }

  // request: landscape.v1.RsvpRequest (JSON) of `device`; answer(choice, data) sends the
  // RsvpAnswer.
  ask(device, request, answer) {
    this.close();
    const deadline = performance.now() + request.timeoutMs;
    $('rsvp-title').textContent = `${device} asks (${request.alarm ? 'alarm' : 'event'} ${request.eventId})`;
    $('rsvp-text').textContent = request.data.join(' ');
    $('rsvp-default').textContent = request.defaultChoice;
    const choices = $('rsvp-choices');
    choices.replaceChildren(...request.choices.map((choice) => {
      const button = document.createElement('button');
      button.textContent = choice;
      button.dataset.choice = choice;
      button.addEventListener('click', () => { answer(choice, request.data); this.close(); });
      return button;
    }));
    const tick = () => {
      const left = Math.max(0, (deadline - performance.now()) / 1000);
      $('rsvp-countdown').textContent = left.toFixed(0);
      if (left <= 0) this.close();
    };
    tick();
    this.current = { rsvpId: request.rsvpId, timer: setInterval(tick, 250) };
    this.dialog.showModal();
  }

  // A landscape.v1.Event: an answer to the open question closes the dialog.
  event(event) {
    if (this.current && event.rsvpAnswer && event.rsvpAnswer.rsvpId === this.current.rsvpId) this.close();
  }

  close() {
    if (!this.current) return;
    clearInterval(this.current.timer);
    this.current = null;
    this.dialog.close();
  }
}
