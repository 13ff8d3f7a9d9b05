// The page: one device at a time (?device=NAME, tabs for the others), fed by the backend's
// WebSocket with that device's live state, events and status reads, and commanding it through
// the same socket.
import './style.css';
import { ToolPanel, IoPanel, SensorPanel } from './cell_panels.js';
import { DeviceContext } from './context.js';
import { Controls } from './controls.js';
import { EventLog } from './event_log.js';
import { JogPendant } from './jog.js';
import { Link, describeStatus } from './link.js';
import { showPerson, showSignIn, whoAmI } from './sign_in.js';
import { PathPanel } from './paths.js';
import { Plots } from './plots.js';
import { RsvpDialog } from './rsvp.js';
import { CellView } from './scene.js';
import { StatePanel } from './state_panel.js';
import { SI, fromSI, poseToSI, toSI } from './units.js';

const $ = (id) => document.getElementById(id);
const FEED_STATE = 'landscape.v1.StateService/StreamState';
const FEED_EVENTS = 'landscape.v1.EventService/Subscribe';
const STATS_KEPT = 5000;

// Milliseconds since the epoch, to the microsecond, of an RFC 3339 timestamp (protobuf JSON).
function timestampMs(text) {
  const match = /^(.*T\d\d:\d\d:\d\d)(\.\d+)?Z$/.exec(text || '');
  if (!match) return NaN;
  return Date.parse(`${match[1]}Z`) + (match[2] ? Number(match[2]) * 1000 : 0);
}

async function main() {
  const person = await whoAmI();
  if (!person) { showSignIn(); return; }
  showPerson(person);
  $('app').hidden = false;
  const devices = await (await fetch('/api/devices')).json();
  const params = new URLSearchParams(location.search);
  const device = params.get('device') || devices[0].name;
  $('devices').replaceChildren(...devices.map((d) => {
    const a = document.createElement('a');
    a.href = `?device=${encodeURIComponent(d.name)}`;
    a.textContent = `${d.name} (${d.target})`;
    a.className = d.name === device ? 'current' : '';
    return a;
  }));

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
  const log = new EventLog();
  const ctx = new DeviceContext(link, device, log, person);
  const view = new CellView($('scene'));
  const state = new StatePanel(ctx);
  const plots = new Plots();
  const rsvp = new RsvpDialog();
  const paths = new PathPanel(ctx, view);
  const controls = new Controls(ctx, { onRsvp: (request, answer) => rsvp.ask(request, answer) });
  new JogPendant(ctx);
  new IoPanel(ctx);
  new SensorPanel(ctx);
  const tools = new ToolPanel(ctx);
  // What the 3D view shows, in one line: the arm, and the cell as its device describes it.
  const showCell = () => {
    const cell = ctx.model.cell;
    const world = cell?.refused ? `no cell description: ${describeStatus(cell.refused)}` : `cell “${cell?.cellName || '…'}”`;
    $('scene-note').textContent = `${ctx.model.robotType || '…'} in ${world}`;
  };
  // What the latency benchmark reads: when each sample's cycle ran and when it arrived here.
  const stats = window.dashboardStats = { samples: [] };
  window.cellView = view;   // the 3D view, for the console and the page tests

  link.onConnection(async (up) => {
    $('connection').textContent = up ? 'connected' : 'disconnected: reconnecting…';
    $('connection').className = `pill ${up ? 'ok' : 'alert'}`;
    if (!up || view.robot) return;
    const description = await ctx.command('GetRobotDescription');
    if (description) state.setLimits(view.loadRobot(description.urdf));
    ctx.model.robotType = description?.robotType || '?';
    showCell();
    ctx.changed('robot');
  });

  link.onFeed((frame) => {
    if (frame.device !== device) return;
    const method = frame.rpc.split('/').pop();
    if (frame.rpc === FEED_STATE) {
      if (frame.status) { $('st-note').textContent = `live state: ${describeStatus(frame.status)}`; return; }
      if (frame.reply.started) {
        ctx.model.started = frame.reply.started;
        $('st-note').textContent = frame.reply.started.note || `live state at ${frame.reply.started.grantedRateHz}/s`;
        return;
      }
      const sample = frame.reply.sample;
      const received = performance.timeOrigin + performance.now();
      const cycle = timestampMs(sample.time);
      stats.samples.push({ sequence: Number(sample.sequence), cycle, received });
      if (stats.samples.length > STATS_KEPT) stats.samples.shift();
      ctx.model.sample = sample;
      const units = sample.units || SI;
      view.setJoints((sample.jointPositions || []).map((q) => toSI(q, 'angular', units)));
      view.setEndEffector(sample.endEffector, sample.endEffectorState);
      if (sample.toolPose) view.setToolPose(poseToSI(sample.toolPose, units));
      state.sample(sample, received - cycle);
      plots.add(sample, performance.now() / 1000, (a) => fromSI(toSI(a, 'angular', units), 'angular', ctx.model.units));
      if (ctx.deviceState !== state.lastState) { state.lastState = ctx.deviceState; ctx.changed('state'); }
    } else if (frame.rpc === FEED_EVENTS) {
      if (frame.status) { log.add('alarm', 3, `event stream: ${describeStatus(frame.status)}`); return; }
      const event = frame.reply.event;
      if (event.stateChange) ctx.lastStateReason = event.stateChange.reason;
      ctx.lastSequence = Math.max(ctx.lastSequence, Number(event.sequence));
      controls.event(event);
      log.addEvent(device, event);
      paths.event(event);
      rsvp.event(event);
    } else if (method === 'GetCellDescription') {
      ctx.model.cell = frame.status ? { refused: frame.status } : frame.reply;
      if (frame.reply) {
        view.setCell(frame.reply);
        tools.setTools(frame.reply.bodies.filter((b) => b.kind === 'KIND_TOOL').map((b) => b.name));
      }
      showCell();
    } else if (method.startsWith('Get')) {
      ctx.model.status[method] = frame.status ? { refused: frame.status } : frame.reply;
      if (method === 'GetUnits' && frame.reply) {
        ctx.model.units = { linear: frame.reply.linearUnits, angular: frame.reply.angularUnits };
      }
      if (method === 'GetToolOffsets' && frame.reply) view.setTipOffset(poseToSI(frame.reply.offset, frame.reply.units));
      state.status();
      ctx.changed('status');
    }
  });
}

main();
