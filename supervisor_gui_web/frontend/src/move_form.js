// Move to a point: a goal in joints, or as a tool tip pose in the base or world frame, typed or
// taken from the arm's current pose, previewed by the ghost arm before anything moves; Move
// sends it as MoveAbsolute. Values are in the device's units.
//
// The ghost stands where the device says the move would end (SolvePose: the move planned and
// checked, not made), or the preview says why the device would refuse it (beyond reach or
// range, a collision). A device without SolvePose: typed joints as they are, a pose solved on
// this page from the arm's present joints (as the device keeps the arm's configuration).
import { poseMatrix } from './arm_view.js';
import { DEVICE } from './context.js';
import { solvePose } from './ik.js';
import { Refused } from './link.js';
import { fmt, fromSI, poseToSI, symbol, toSI } from './units.js';

const $ = (id) => document.getElementById(id);
const JOINT = 'REFERENCE_FRAME_JOINT_FRAME';
const WORLD = 'REFERENCE_FRAME_WORLD_CARTESIAN_FRAME';
const POSE = ['x', 'y', 'z', 'roll', 'pitch', 'yaw'];
const PREVIEW_MS = 150;
const UNIMPLEMENTED = 12;

export class MoveForm {
  constructor(selection) {
    this.selection = selection;
    this.inputs = POSE.map((_, i) => $(`move-v${i}`));
    this.world = null;    // the device's world frame in its base (a Matrix4), once asked
    $('move-frame').addEventListener('change', () => { this.labels(); this.fromCurrent(); });
    $('btn-move-from-current').addEventListener('click', () => this.fromCurrent());
    $('btn-move').addEventListener('click', () => this.move());
    $('btn-move-clear').addEventListener('click', () => this.clear());
    for (const input of this.inputs) input.addEventListener('input', () => this.schedule());
    for (const id of ['move-motion', 'move-speed']) $(id).addEventListener('input', () => this.schedule());
    this.asked = 0;       // the newest preview; an older answer arriving later gives way
    selection.on((what, device) => {
      if (what === 'switch') {
        for (const other of selection.devices.values()) if (other !== device) other.arm.showGhost(null);
        this.world = null;
        this.clear();
      }
      if (device === selection.device && ['switch', 'status'].includes(what)) this.labels();
    });
    this.labels();
  }

  get frame() { return $('move-frame').value; }

  labels() {
    const units = this.selection.ctx.model.units;
    const names = this.frame === JOINT ? ['J1', 'J2', 'J3', 'J4', 'J5', 'J6'] : POSE;
    names.forEach((name, i) => {
      const kind = this.frame === JOINT || i > 2 ? 'angular' : 'linear';
      $(`move-l${i}`).textContent = `${name} (${symbol(units[kind])})`;
    });
  }

  values() { return this.inputs.map((input) => (input.value.trim() === '' ? NaN : Number(input.value))); }

  // The arm's pose now, in the form's frame and the device's units.
  async fromCurrent() {
    const { ctx } = this.selection.device;
    const sample = ctx.model.sample;
    const units = ctx.model.units;
    let values = null;
    if (this.frame === WORLD) {
      const position = await ctx.command('GetRobotPosition');
      if (position) values = POSE.map((k, i) => fromSI(toSI(position.worldPosition[k], i < 3 ? 'linear' : 'angular', position.units), i < 3 ? 'linear' : 'angular', units));
    } else if (sample && this.frame === JOINT) {
      values = sample.jointPositions.map((q) => fromSI(q, 'angular', units));
    } else if (sample?.toolPose) {   // the stream's tool pose is in the base frame, SI
      values = POSE.map((k, i) => fromSI(sample.toolPose[k], i < 3 ? 'linear' : 'angular', units));
    }
    if (!values) return;
    values.forEach((v, i) => { this.inputs[i].value = fmt(v, 4); });
    this.schedule();
  }

  schedule() {
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.preview(), PREVIEW_MS);
  }

  // The goal's joints (rad) for the ghost, as the device solves the move.
  async goalJoints() {
    const values = this.values();
    if (!values.every(Number.isFinite)) return { joints: null, why: 'six numbers are needed' };
    const { ctx } = this.selection.device;
    const request = { frame: this.frame, values, motionType: $('move-motion').value };
    const speed = $('move-speed').value;
    if (speed !== '') request.speed = Number(speed);
    let answer;
    try {
      answer = await ctx.link.call(ctx.device, `${DEVICE}SolvePose`, request);
    } catch (error) {
      if (!(error instanceof Refused)) throw error;
      if (error.status.code === UNIMPLEMENTED) return this.solvedHere(values);
      return { joints: null, why: `the device did not solve it: ${error.status.message}` };
    }
    if (!answer.reachable) return { joints: null, why: `the device would refuse this move: ${answer.refusal.message}` };
    return { joints: answer.joints.map((q) => toSI(q, 'angular', answer.units)),
      why: `the goal as the device solves it, a move of ${answer.duration.toFixed(1)} s` };
  }

  // Without SolvePose: typed joints, or a pose solved from the arm's present joints.
  async solvedHere(values) {
    const device = this.selection.device;
    const units = device.ctx.model.units;
    if (this.frame === JOINT) return { joints: values.map((v) => toSI(v, 'angular', units)), why: 'the goal' };
    const pose = poseToSI(Object.fromEntries(POSE.map((k, i) => [k, values[i]])), units);
    let target = poseMatrix(pose);
    if (this.frame === WORLD) {
      this.world = this.world || await device.worldInBase();
      if (!this.world) return { joints: null, why: 'the device did not give its world frame' };
      target = this.world.clone().multiply(target);
    }
    const arm = device.arm;
    const now = (device.ctx.model.sample?.jointPositions || []).slice();
    const toolOffset = device.toolOffset();
    const joints = now.length ? solvePose((q) => arm.tipMatrix(q, toolOffset), target, now, device.limits) : null;
    return joints ? { joints, why: 'the goal, solved on this page from the arm\'s present configuration' }
      : { joints: null, why: 'no joint values found for this pose from the arm\'s present configuration: the device judges it when you press Move' };
  }

  async preview() {
    const arm = this.selection.device.arm;
    if (!arm.robot) return;
    const asked = ++this.asked;
    const { joints, why } = await this.goalJoints();
    if (asked !== this.asked) return;
    arm.showGhost(joints);
    this.ghostJoints = joints;
    $('move-preview').textContent = joints ? `Ghost arm: ${why}.` : `No preview: ${why}.`;
  }

  async move() {
    const request = { pointName: 'move-to-point', frame: this.frame, values: this.values(),
      motionType: $('move-motion').value };
    const speed = $('move-speed').value;
    if (speed !== '') request.speed = Number(speed);
    await this.selection.ctx.command('MoveAbsolute', request);
  }

  clear() {
    this.asked += 1;   // a preview under way is not shown
    this.selection.device.arm.showGhost(null);
    this.ghostJoints = null;
    $('move-preview').textContent = '';
  }
}
