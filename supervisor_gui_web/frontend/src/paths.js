// Paths: teach (store the current pose as a tag of a named path), load points typed in, clear,
// run, stop, resume, abort, and the progress by tag of the newest PathMove of any client, from
// the event stream. The page keeps the tags of the paths it loaded (the contract has no call to
// list a stored path's points), and draws them in the 3D view.
import { poseMatrix } from './scene.js';
import { fromSI, poseToSI, toSI } from './units.js';

const $ = (id) => document.getElementById(id);
const ENDED = new Set(['done', 'failed', 'aborted']);

export class PathPanel {
  constructor(ctx, view) {
    this.ctx = ctx;
    this.view = view;
    this.paths = new Map();      // path name -> {frame, tags: [TagStruct JSON]}
    this.run = null;             // {commandId, path, phase, reached: [[tag index, name]] in order}
    this.drawn = 0;              // the newest draw; an older one still computing gives way
    const on = (id, handler) => $(id).addEventListener('click', handler);
    on('btn-teach', () => this.teach());
    on('btn-path-load', () => this.loadTyped());
    on('btn-path-clear', () => this.clear());
    on('btn-path-run', () => this.start());
    on('btn-stop', () => ctx.command('StopMotion'));
    on('btn-resume', () => ctx.command('ResumeMotion'));
    on('btn-abort', () => ctx.command('AbortMotion'));
    $('path-name').addEventListener('input', () => this.show());
  }

  async load(name, frame, motionType, tags) {
    const header = { pathName: name, frame, motionType, offsetType: 'OFFSET_TYPE_ABSOLUTE_DATA', numberOfPoints: tags.length };
    const reply = await this.ctx.command('PathLoad', [{ header, tags }], { streamed: true });
    if (!reply) return false;
    const known = this.paths.get(name);
    const base = known && known.frame === frame ? known.tags : [];
    this.paths.set(name, { frame, tags: [...base, ...tags] });
    this.show();
    return true;
  }

  // The current joint values, in the device's units, as one more tag of the named path.
  teach() {
    const sample = this.ctx.model.sample;
    if (!sample) return;
    const units = this.ctx.model.units;
    const name = $('path-name').value;
    const count = this.paths.get(name)?.tags.length || 0;
    const tagName = $('teach-tag').value || `t${count + 1}`;
    const jointValues = sample.jointPositions.map((q) => fromSI(toSI(q, 'angular', sample.units), 'angular', units));
    $('teach-tag').value = '';
    return this.load(name, 'REFERENCE_FRAME_JOINT_FRAME', 'MOTION_TYPE_JOINT_MOTION', [{ tagName, tagIndex: count, jointValues }]);
  }

  // Lines "tag v1 … v6" in the device's units: joint values, or x y z roll pitch yaw.
  loadTyped() {
    const frame = $('path-frame').value;
    const tags = [];
    $('path-points').value.split('\n').map((l) => l.trim()).filter(Boolean).forEach((line, i) => {
      const [tagName, ...rest] = line.split(/\s+/);
      const values = rest.map(Number);
      const tag = { tagName, tagIndex: i };
      if (frame === 'REFERENCE_FRAME_JOINT_FRAME') tag.jointValues = values;
      else ['x', 'y', 'z', 'roll', 'pitch', 'yaw'].forEach((k, j) => { tag[k] = values[j]; });
      tags.push(tag);
    });
    // Bad numbers go to the server as they are (NaN as JSON null fails to parse there too).
    return this.load($('path-name').value, frame, $('path-motion').value, tags);
  }

  async clear() {
    const name = $('path-name').value;
    if (await this.ctx.command('PathClearPath', { pathName: name })) {
      this.paths.delete(name);
      this.show();
    }
  }

  async start() {
    const name = $('path-name').value;
    const reply = await this.ctx.command('PathMove', { pathName: name, numberOfCycles: Number($('path-cycles').value) });
    if (reply && this.run?.commandId !== reply.retVal.commandId) this.follow(reply.retVal.commandId, name);
  }

  follow(commandId, path) {
    this.run = { commandId, path, reached: [], phase: 'started' };
  }

  // A landscape.v1.Event: a PathMove started by any client (its point name is the path's), the
  // tags it reaches and its end.
  event(event) {
    const c = event.command;
    if (!c || c.command !== 'PathMove') return;
    if (c.phase === 'PHASE_STARTED' && this.run?.commandId !== c.commandId) this.follow(c.commandId, c.pointName);
    if (c.commandId !== this.run?.commandId) return;
    if (c.phase === 'PHASE_TAG_REACHED') this.run.reached.push([c.tagIndex, c.tagName]);
    else this.run.phase = c.phase.replace('PHASE_', '').toLowerCase();
    this.show();
  }

  // The newest run (once it ended, unless another path this page loaded is typed), by its
  // path's tags when the page knows them, else by the tags reached so far; otherwise the typed
  // path's tags. The path shown is drawn.
  show() {
    const typed = $('path-name').value;
    const other = typed !== this.run?.path && this.paths.has(typed);
    const run = this.run && !(other && ENDED.has(this.run.phase)) ? this.run : null;
    const name = run ? run.path : typed;
    const path = this.paths.get(name);
    const box = $('path-progress');
    box.replaceChildren();
    if (run) {
      const head = document.createElement('div');
      head.textContent = `run ${run.commandId} of ${run.path}: ${run.phase}, ${run.reached.length}${path ? '/' + path.tags.length : ''} tags reached`;
      box.append(head);
    }
    // A path the page loaded has its tags numbered 0, 1, ...; another's are shown as reached.
    const reached = new Set(run?.reached.map(([i]) => i));
    const tags = path ? path.tags.map((tag, i) => [i, tag.tagName || `#${i}`]) : run?.reached || [];
    for (const [i, tagName] of tags) {
      const item = document.createElement('span');
      item.className = `tag ${reached.has(i) ? 'reached' : ''}`;
      item.textContent = tagName;
      box.append(item);
    }
    this.draw(path);
  }

  // The loaded points as tool tip positions in the base frame (meters): joint values through
  // the arm's kinematics, base points as they are, world points through the device's world
  // frame.
  async draw(path) {
    const drawing = ++this.drawn;
    if (!path || !this.view.robot) { this.view.setPath([]); return; }
    const units = this.ctx.model.units;
    const toolOffset = this.toolOffset();
    const world = path.frame === 'REFERENCE_FRAME_WORLD_CARTESIAN_FRAME' ? await this.worldInBase(toolOffset) : null;
    if (drawing !== this.drawn) return;
    const points = path.tags.map((tag) => {
      if (path.frame === 'REFERENCE_FRAME_JOINT_FRAME') {
        return this.view.tipAt(tag.jointValues.map((v) => toSI(v, 'angular', units)), toolOffset);
      }
      const p = poseToSI({ x: tag.x, y: tag.y, z: tag.z, roll: 0, pitch: 0, yaw: 0 }, units);
      const point = { x: p.x, y: p.y, z: p.z };
      return world ? this.view.transformed(point, world) : point;
    });
    this.view.setPath(points);
  }

  toolOffset() {
    const offset = this.ctx.model.status.GetToolOffsets;
    return offset?.offset ? poseToSI(offset.offset, offset.units) : { x: 0, y: 0, z: 0, roll: 0, pitch: 0, yaw: 0 };
  }

  // The device's world Cartesian frame in its base frame (SetWorldCartesianFrame, which has no
  // get): from one GetRobotPosition, the tool tip in the base (the arm's kinematics at its
  // joints) times the inverse of the tip in the world.
  async worldInBase(toolOffset) {
    const position = await this.ctx.command('GetRobotPosition');
    if (!position) return null;
    const joints = position.jointPosition.map((q) => toSI(q, 'angular', position.units));
    const tipInWorld = poseMatrix(poseToSI(position.worldPosition, position.units));
    return this.view.tipMatrix(joints, toolOffset).multiply(tipInWorld.invert());
  }
}
