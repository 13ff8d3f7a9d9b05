// The live log of events and alarms (EventService.Subscribe) of every device, and the page's
// refused commands, with filters by kind, severity and text; in words, newest first.
import { phaseWord, readable, severityWord, stateWord } from './words.js';

const MAX_ENTRIES = 1000;
const SEVERITY = { ALARM_SEVERITY_INFO: 1, ALARM_SEVERITY_WARNING: 2, ALARM_SEVERITY_ERROR: 3, ALARM_SEVERITY_CRITICAL: 4 };
const KIND_OF_DETAIL = {
  command: 'command', alarm: 'alarm', stateChange: 'state', digitalIo: 'io',
  rsvpRequest: 'rsvp', rsvpAnswer: 'rsvp', eventsLost: 'alarm', operatorMessage: 'message',
};

function summary(event) {
  if (event.command) {
    const c = event.command;
    const tag = c.phase === 'PHASE_TAG_REACHED' ? ` tag ${c.tagName} (#${c.tagIndex})` : ` ${phaseWord(c.phase)}`;
    return `${c.command} ${c.pointName}${tag} [${c.commandId}]${c.message ? ': ' + readable(c.message) : ''}`;
  }
  if (event.alarm) return `${severityWord(event.alarm.severity)} ${event.alarm.code}: ${readable(event.alarm.message)}`;
  if (event.stateChange) {
    const s = event.stateChange;
    return `${stateWord(s.fromState)} → ${stateWord(s.toState)} (${readable(s.reason)})`;
  }
  if (event.rsvpRequest) return `asks: ${event.rsvpRequest.data.join(' ')} [${event.rsvpRequest.choices.join(' / ')}]`;
  if (event.rsvpAnswer) {
    const a = event.rsvpAnswer;
    return a.timedOut ? `timed out: the device took its default, ${a.choice}` : `answered ${a.choice}`;
  }
  if (event.operatorMessage) return `${event.operatorMessage.source}: ${event.operatorMessage.text}`;
  if (event.eventsLost) return `events ${event.eventsLost.firstSequence}–${event.eventsLost.lastSequence} lost`;
  return event.data.join(' ');
}

export class EventLog {
  constructor() {
    this.list = document.getElementById('log');
    this.kinds = [...document.querySelectorAll('.log-filters input[data-kind]')];
    this.severity = document.getElementById('log-severity');
    this.text = document.getElementById('log-text');
    for (const input of [...this.kinds, this.severity, this.text]) input.addEventListener('input', () => this.refilter());
    // Events shown, by device, sequence and time: a replay after a reconnect is not shown
    // twice, and a restarted device's events (sequences from 1 again) are still shown.
    this.seen = new Set();
  }

  // A landscape.v1.Event (JSON) of `device`.
  addEvent(device, event) {
    const sequence = Number(event.sequence);
    const key = `${device} ${sequence} ${event.time}`;
    if (this.seen.has(key)) return;
    this.seen.add(key);
    if (this.seen.size > 2 * MAX_ENTRIES) this.seen.delete(this.seen.values().next().value);
    const time = Date.parse(event.time);
    const detail = Object.keys(KIND_OF_DETAIL).find((key) => event[key]);
    const kind = detail ? KIND_OF_DETAIL[detail] : 'command';
    const severity = event.alarm ? SEVERITY[event.alarm.severity] || 0 : 0;
    this.add(kind, severity, `${device} ${event.eventId.replaceAll('_', ' ')}: ${summary(event)}`, time, `#${sequence}`);
  }

  // A refusal: what the person did and why; the machine's codes in small print.
  addRefused(text, codes = '') {
    const item = this.add('refused', 3, `refused: ${text}`);
    if (!codes) return;
    const small = document.createElement('small');
    small.className = 'codes';
    small.textContent = ` [${codes}]`;
    item.lastChild.append(small);
  }

  // One line: its time, its number (an event's sequence), the text.
  add(kind, severity, text, time = Date.now(), number = '') {
    const item = document.createElement('li');
    item.dataset.kind = kind;
    item.dataset.severity = severity;
    item.className = `log-${kind} sev-${severity}`;
    const when = document.createElement('time');
    when.textContent = new Date(time).toLocaleTimeString();
    const seq = document.createElement('span');
    seq.className = 'seq';
    seq.textContent = number;
    const words = document.createElement('span');
    words.textContent = text;
    item.append(when, seq, words);
    item.hidden = !this.shows(item);
    this.list.prepend(item);
    while (this.list.childElementCount > MAX_ENTRIES) this.list.lastElementChild.remove();
    return item;
  }

  shows(item) {
    const kinds = new Set(this.kinds.filter((k) => k.checked).map((k) => k.dataset.kind));
    const text = this.text.value.trim().toLowerCase();
    return kinds.has(item.dataset.kind) && Number(item.dataset.severity) >= Number(this.severity.value)
      && (!text || item.textContent.toLowerCase().includes(text));
  }

  refilter() {
    for (const item of this.list.children) item.hidden = !this.shows(item);
  }
}
