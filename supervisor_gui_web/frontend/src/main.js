// The page: every device of the supervisor at a glance (the status bar) and in 3D, the chosen
// one's panels, fed by the backend's WebSocket with each device's live state, events and
// status reads, and commanding it through the same socket.
import './style.css';
import { Access } from './access.js';
import { AlarmPanel } from './alarms.js';
import { ToolPanel, IoPanel, SensorPanel } from './cell_panels.js';
import { Controls } from './controls.js';
import { Device } from './device.js';
import { EventLog } from './event_log.js';
import { ControlRequests, HandoverPanel } from './handover.js';
import { JogPendant } from './jog.js';
import { Link } from './link.js';
import { MoveForm } from './move_form.js';
import { PathPanel } from './path_panel.js';
import { Plots } from './plots.js';
import { RecordsPanel } from './records.js';
import { Refusals } from './refusal.js';
import { RsvpDialog } from './rsvp.js';
import { Scenes } from './scenes.js';
import { Selection } from './selection.js';
import { showPerson, showSignIn, whoAmI } from './sign_in.js';
import { StatePanel } from './state_panel.js';
import { StatusBar } from './status_bar.js';

const $ = (id) => document.getElementById(id);

function connectLink() {
  const link = new Link(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`);
  link.onSignedOut = (why) => showSignIn(`Your sign-in ended: ${why}`);
  link.mayReconnect = async () => {
    try {
      if (await whoAmI()) return true;
    } catch {
      return true;   // the supervisor is not there: try again
    }
    showSignIn('Your sign-in ended: sign in again.');
    return false;
  };
  link.onConnection((up) => {
    $('connection').textContent = up ? 'supervisor connected' : 'supervisor disconnected: reconnecting…';
    $('connection').className = `pill ${up ? 'ok' : 'alert'}`;
  });
  return link;
}

async function main() {
  const person = await whoAmI();
  if (!person) { showSignIn(); return; }
  showPerson(person);
  $('app').hidden = false;
  // The panels' column scrolls below the top, whose height changes (arms, banners, wrapping).
  new ResizeObserver(([entry]) => document.documentElement.style.setProperty(
    '--top-h', `${Math.ceil(entry.target.getBoundingClientRect().height)}px`)).observe($('top'));
  const list = await (await fetch('/api/devices')).json();
  const log = new EventLog();
  // What the latency benchmark reads: when each sample's cycle ran and when it arrived here.
  const stats = window.dashboardStats = { samples: [] };
  const page = { link: connectLink(), log, person, refusals: new Refusals(log), rsvp: new RsvpDialog(), stats };
  const devices = new Map(list.map((entry) => [entry.name, new Device(page, entry)]));
  for (const device of devices.values()) device.handover = new ControlRequests(device);
  const selection = new Selection(devices);
  const wanted = new URLSearchParams(location.search).get('device');
  if (wanted) selection.select(wanted);

  new Scenes($('scenes'), selection);
  new StatusBar(selection, () => { $('panel-alarms').open = true; $('panel-alarms').scrollIntoView(); });
  new StatePanel(selection);
  new Controls(selection);
  new HandoverPanel(selection);
  new MoveForm(selection);
  new JogPendant(selection);
  new PathPanel(selection);
  new AlarmPanel(selection);
  new ToolPanel(selection);
  new IoPanel(selection);
  new SensorPanel(selection);
  new RecordsPanel(selection);
  new Access(selection, person);
  const plots = window.livePlots = new Plots();   // (and for the page tests)
  selection.on((what, device) => {
    if (device === selection.device && ['sample', 'switch', 'status'].includes(what)) {
      plots.show(device.plotData, device.ctx.model.units);
    }
    if (what === 'switch') $('panels-device').textContent = device.name;
  });
  selection.emit('switch', selection.device);
  page.link.onFeed((frame) => devices.get(frame.device)?.feed(frame));
}

main();
