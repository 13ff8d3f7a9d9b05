// Move to a point: a goal in joints, or as a tool tip pose in the base or world frame, typed or
// taken from the arm's current pose, previewed by the ghost arm before anything moves; Move
// sends it as MoveAbsolute. Values are in the device's units.
import { poseMatrix } from './arm_view.js';
import { solvePose } from './ik.js';
import { fmt, fromSI, poseToSI, symbol, toSI } from './units.js';

const $ = (id) => document.getElementById(id);
const JOINT = 'REFERENCE_FRAME_JOINT_FRAME';
const WORLD = 'REFERENCE_FRAME_WORLD_CARTESIAN_FRAME';
const POSE = ['x', 'y', 'z', 'roll', 'pitch', 'yaw'];
const PREVIEW_MS = 150;

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

  // The goal's joints (rad) for the ghost: typed, or solved from the arm's present joints.
  async goalJoints() {
    const device = this.selection.device;
    const units = device.ctx.model.units;
    const values = this.values();
    if (!values.every(Number.isFinite)) return { joints: null, why: 'six numbers are needed' };
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
    const { joints, why } = await this.goalJoints();
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
    this.selection.device.arm.showGhost(null);
    this.ghostJoints = null;
    $('move-preview').textContent = '';
  }
}
