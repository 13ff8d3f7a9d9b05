// Paths: teach (store the current pose as a tag of a named path), load points typed in, clear,
// run, stop, resume, abort, and the run's progress by tag from the event stream. The page keeps
// the tags of the paths it loaded (the contract has no call to list a stored path's points), and
// draws them in the 3D view.
import { fromSI, poseToSI, toSI } from './units.js';

const $ = (id) => document.getElementById(id);

export class PathPanel {
  constructor(ctx, view) {
    this.ctx = ctx;
    this.view = view;
    this.paths = new Map();      // path name -> {frame, tags: [TagStruct JSON]}
    this.run = null;             // {commandId, path, reached: Set of tag indexes}
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
    if (reply) {
      this.run = { commandId: reply.retVal.commandId, path: name, reached: new Set(), phase: 'started' };
      this.show();
    }
  }

  // A landscape.v1.Event: tag arrivals and the end of the page's run.
  event(event) {
    const c = event.command;
    if (!c || !this.run || c.commandId !== this.run.commandId) return;
    if (c.phase === 'PHASE_TAG_REACHED') this.run.reached.add(c.tagIndex);
    else this.run.phase = c.phase.replace('PHASE_', '').toLowerCase();
    this.show();
  }

  show() {
    const name = $('path-name').value;
    const path = this.paths.get(name);
    const box = $('path-progress');
    box.replaceChildren();
    const run = this.run && this.run.path === name ? this.run : null;
    if (run) {
      const head = document.createElement('div');
      head.textContent = `run ${run.commandId}: ${run.phase}, ${run.reached.size}${path ? '/' + path.tags.length : ''} tags reached`;
      box.append(head);
    }
    for (const [i, tag] of (path?.tags || []).entries()) {
      const item = document.createElement('span');
      item.className = `tag ${run?.reached.has(i) ? 'reached' : ''}`;
      item.textContent = tag.tagName || `#${i}`;
      box.append(item);
    }
    this.draw(path);
  }

  // The loaded points as tool tip positions in the base frame (meters).
  draw(path) {
    if (!path || !this.view.robot) { this.view.setPath([]); return; }
    const units = this.ctx.model.units;
    const offset = this.ctx.model.status.GetToolOffsets;
    const toolOffset = offset?.offset ? poseToSI(offset.offset, offset.units) : { x: 0, y: 0, z: 0, roll: 0, pitch: 0, yaw: 0 };
    const points = path.tags.map((tag) => {
      if (path.frame === 'REFERENCE_FRAME_JOINT_FRAME') {
        return this.view.tipAt(tag.jointValues.map((v) => toSI(v, 'angular', units)), toolOffset);
      }
      // World points are drawn as base points: exact while the world frame is the base frame.
      const p = poseToSI({ x: tag.x, y: tag.y, z: tag.z, roll: 0, pitch: 0, yaw: 0 }, units);
      return { x: p.x, y: p.y, z: p.z };
    });
    this.view.setPath(points);
  }
}
