// One device as the page follows it: its context (model, session, lock), how fresh its data
// is, its alarms, paths and plot series, its arm in 3D; and the backend's frames for it
// (live state, events, status reads, the cell, the supervisor's own notes) sorted to them.
import { AlarmBook } from './alarms.js';
import { DeviceContext } from './context.js';
import { Freshness } from './freshness.js';
import { PathBook } from './paths.js';
import { PlotData } from './plots.js';
import { DeviceSession } from './session.js';
import { ArmView, poseMatrix } from './arm_view.js';
import { poseToSI, toSI } from './units.js';
import { explainLine, readable } from './words.js';

const FEED_STATE = 'landscape.v1.StateService/StreamState';
const FEED_EVENTS = 'landscape.v1.EventService/Subscribe';
const SUPERVISOR = 'supervisor/';
const STATS_KEPT = 5000;

// Milliseconds since the epoch, to the microsecond, of an RFC 3339 timestamp (protobuf JSON).
export function timestampMs(text) {
  const match = /^(.*T\d\d:\d\d:\d\d)(\.\d+)?Z$/.exec(text || '');
  if (!match) return NaN;
  return Date.parse(`${match[1]}Z`) + (match[2] ? Number(match[2]) * 1000 : 0);
}

export class Device {
  // page: {link, log, person, refusals, rsvp, stats}; name and target from /api/devices.
  constructor(page, { name, target }) {
    this.name = name;
    this.target = target;
    this.stats = page.stats;
    this.rsvp = page.rsvp;
    const ctx = this.ctx = new DeviceContext(page.link, name, page.log, page.person, page.refusals);
    this.fresh = new Freshness();
    this.session = new DeviceSession(ctx, (device, request, answer) => {
      page.rsvp.ask(device, request, answer);
      this.alarms.asked(request, answer);
    });
    this.alarms = new AlarmBook(ctx);
    this.paths = new PathBook(ctx);
    this.plotData = new PlotData();
    this.arm = new ArmView(name, () => {});
    this.note = '';        // what the state stream said of itself (its rate, a failure)
    this.fresh.onChange((change) => {
      this.arm.setStale(change.stale);
      if (change.back) {
        page.log.add('state', 0, `${name}: ${change.back}`);
        this.session.notice.cameBack(change.back);
      }
      ctx.changed('fresh');
    });
    page.link.onConnection((up) => {
      if (!up) this.fresh.linkDown();
      else if (!this.arm.robot) this.loadRobot();
    });
  }

  async loadRobot() {
    const description = await this.ctx.command('GetRobotDescription');
    if (!description || this.arm.robot) return;
    this.limits = this.arm.loadRobot(description.urdf);
    this.ctx.model.robotType = description.robotType || '?';
    if (this.ctx.model.cell && !this.ctx.model.cell.refused) this.arm.setCell(this.ctx.model.cell);
    this.ctx.changed('robot');
    this.paths.refresh();   // the device answers: its stored paths
  }

  // One frame of the backend about this device.
  feed(frame) {
    const method = frame.rpc.split('/').pop();
    if (frame.rpc === FEED_STATE) this.state(frame);
    else if (frame.rpc === FEED_EVENTS) this.event(frame);
    else if (frame.rpc.startsWith(SUPERVISOR)) this.supervisor(method, frame.reply || {});
    else if (method === 'GetCellDescription') {
      const known = this.ctx.model.cell && !this.ctx.model.cell.refused;
      if (frame.status && known) return;   // the device is away: the cell it gave stays drawn
      this.ctx.model.cell = frame.status ? { refused: frame.status } : frame.reply;
      if (frame.reply && this.arm.robot) this.arm.setCell(frame.reply);
      this.ctx.changed('cell');
    } else if (method.startsWith('Get')) this.status(method, frame);
  }

  state(frame) {
    const ctx = this.ctx;
    if (frame.status) {
      this.note = `live state: ${explainLine(frame.status)}`;
      this.fresh.failed(frame.status);
      ctx.changed('note');
      return;
    }
    if (frame.reply.started) {
      ctx.model.started = frame.reply.started;
      this.note = frame.reply.started.note || `live state at ${frame.reply.started.grantedRateHz}/s`;
      ctx.changed('note');
      return;
    }
    const sample = frame.reply.sample;
    const received = performance.timeOrigin + performance.now();
    const cycle = timestampMs(sample.time);
    this.stats.samples.push({ device: this.name, sequence: Number(sample.sequence), cycle, received });
    if (this.stats.samples.length > STATS_KEPT) this.stats.samples.shift();
    const stateBefore = ctx.deviceState;
    ctx.model.sample = sample;
    this.age = received - cycle;
    this.fresh.sample(sample, cycle);
    const units = sample.units;   // the backend asks for meters and radians (device_hub.py)
    this.arm.setJoints((sample.jointPositions || []).map((q) => toSI(q, 'angular', units)));
    this.arm.setEndEffector(sample.endEffector, sample.endEffectorState);
    if (sample.toolPose) this.arm.setToolPose(poseToSI(sample.toolPose, units));
    this.plotData.add(sample, performance.now() / 1000);
    ctx.changed('sample');
    if (ctx.deviceState !== stateBefore) ctx.changed('state');
  }

  event(frame) {
    const ctx = this.ctx;
    if (frame.status) {
      ctx.log.add('alarm', 3, `${this.name} event stream: ${explainLine(frame.status)}`);
      return;
    }
    const event = frame.reply.event;
    if (event.stateChange) ctx.lastStateReason = readable(event.stateChange.reason);
    ctx.lastSequence = Math.max(ctx.lastSequence, Number(event.sequence));
    this.session.event(event);
    ctx.log.addEvent(this.name, event);
    this.paths.event(event);
    this.alarms.event(event);
    this.rsvp.event(event);
    ctx.changed('event');
  }

  status(method, frame) {
    const ctx = this.ctx;
    ctx.model.status[method] = frame.status ? { refused: frame.status } : frame.reply;
    if (method === 'GetUnits' && frame.reply) {
      ctx.model.units = { linear: frame.reply.linearUnits, angular: frame.reply.angularUnits };
    }
    if (method === 'GetToolOffsets' && frame.reply) this.arm.setTipOffset(poseToSI(frame.reply.offset, frame.reply.units));
    ctx.changed('status');
  }

  // The supervisor's own frames about this device: control requests.
  supervisor(method, reply) {
    if (method === 'Control') this.handover?.notice(reply);
  }

  // The tool tip's offset in the flange frame (SI), as GetToolOffsets says; none: zero.
  toolOffset() {
    const offset = this.ctx.model.status.GetToolOffsets;
    return offset?.offset ? poseToSI(offset.offset, offset.units) : { x: 0, y: 0, z: 0, roll: 0, pitch: 0, yaw: 0 };
  }

  // The device's world Cartesian frame in its base frame (SetWorldCartesianFrame, which has no
  // get): from one GetRobotPosition, the tool tip in the base (the arm's kinematics at its
  // joints) times the inverse of the tip in the world. Null when refused.
  async worldInBase() {
    const position = await this.ctx.command('GetRobotPosition');
    if (!position || !this.arm.robot) return null;
    const joints = position.jointPosition.map((q) => toSI(q, 'angular', position.units));
    const tipInWorld = poseMatrix(poseToSI(position.worldPosition, position.units));
    return this.arm.tipMatrix(joints, this.toolOffset()).multiply(tipInWorld.invert());
  }
}
