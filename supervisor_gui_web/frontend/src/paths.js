// One device's paths, and the progress of its newest path run.
//
// The list is the device's (DeviceService.ListPaths: each stored path's name, motion type and
// count of points and tags, whoever loaded it), read when the page connects and after it loads
// or clears a path or sees an unknown one run. A path's points are read (GetPath: resolved to
// joints, in the device's units) when it is previewed or runs; points the page loaded itself
// are known already. A device that cannot list its paths (an older one) leaves the paths the
// page knows: loaded or taught here, or seen running. A run's progress comes from the event
// stream, whoever started it: the tags reached in the current cycle, out of the path's tags
// when the page knows every point. A tag is known by its name and index (a client may leave
// every index 0); reaching one already reached in this cycle starts the next.
import { DEVICE } from './context.js';
import { Refused } from './link.js';
import { phaseWord } from './words.js';

export const ENDED = new Set(['done', 'failed', 'aborted']);
const RUNNING = new Set(['PHASE_STARTED', 'PHASE_RESUMED']);
const JOINT_FRAME = 'REFERENCE_FRAME_JOINT_FRAME';
const STORED = 'stored on the device';

// A tag as its events name it (TagStruct JSON and CommandEvent spell both fields alike).
export const tagKey = (tag) => `${tag.tagIndex || 0}:${tag.tagName}`;

export class PathBook {
  constructor(ctx) {
    this.ctx = ctx;
    this.paths = new Map();   // name -> {frame, motionType, tags, length (device's), source, units?}
    this.run = null;          // {commandId, path, phase, cycles, cycle, reached: Set, last}
    this.unlisted = '';       // why the device did not list its paths, if it did not
  }

  // The device's list (ListPaths); the points the page knows of a path it lists whole stay.
  async refresh() {
    let reply;
    try {
      reply = await this.ctx.link.call(this.ctx.device, `${DEVICE}ListPaths`, {});
    } catch (error) {
      if (!(error instanceof Refused)) throw error;
      this.unlisted = error.status.message;
      this.ctx.changed('paths');
      return;
    }
    const listed = new Map();
    for (const summary of reply.paths) {
      const known = this.paths.get(summary.name);
      const whole = known && known.length === summary.numberOfPoints && known.tags.length === summary.numberOfPoints;
      listed.set(summary.name, whole ? { ...known, source: STORED }
        : { frame: JOINT_FRAME, motionType: summary.motionType, tags: [], length: summary.numberOfPoints, source: STORED });
    }
    this.paths = listed;
    this.unlisted = '';
    this.ctx.changed('paths');
  }

  // A stored path's points (GetPath), resolved to joints; null, or the refusal's Status.
  async read(name) {
    let replies;
    try {
      replies = await this.ctx.link.collect(this.ctx.device, `${DEVICE}GetPath`, { pathName: name });
    } catch (error) {
      if (!(error instanceof Refused)) throw error;
      return error.status;
    }
    const [first] = replies;
    this.paths.set(name, { frame: JOINT_FRAME, motionType: first.path.motionType, tags: replies.flatMap((r) => r.points),
      length: first.path.numberOfPoints, units: first.units, source: STORED });
    this.ctx.changed('paths');
    return null;
  }

  // Whether every point of a path is known here.
  whole(name) {
    const path = this.paths.get(name);
    return Boolean(path) && path.length === path.tags.length;
  }

  // PathLoad of `tags` (TagStruct JSON, device units) onto path `name`; true when loaded.
  async load(name, frame, motionType, tags) {
    const header = { pathName: name, frame, motionType, offsetType: 'OFFSET_TYPE_ABSOLUTE_DATA', numberOfPoints: tags.length };
    const reply = await this.ctx.command('PathLoad', [{ header, tags }], { streamed: true });
    if (!reply) return false;
    const known = this.paths.get(name);
    // Points appended to what the page knows in the same frame; otherwise only the new ones
    // are known (the device resolves every point to joints, whatever its frame).
    const base = known && known.frame === frame ? known.tags : [];
    this.paths.set(name, { frame, motionType, tags: [...base, ...tags], length: reply.pathLength, source: 'loaded here' });
    this.ctx.changed('paths');
    await this.refresh();
    await this.readIfListed(name);   // the points stored before this load, too
    return true;
  }

  async clear(name) {
    if (!await this.ctx.command('PathClearPath', { pathName: name })) return false;
    this.paths.delete(name);
    this.ctx.changed('paths');
    await this.refresh();
    return true;
  }

  async start(name, cycles) {
    const reply = await this.ctx.command('PathMove', { pathName: name, numberOfCycles: cycles });
    if (!reply) return reply;
    // Its started event may have come first: the run is followed already, without its cycles.
    if (this.run?.commandId === reply.retVal.commandId) this.run.cycles = cycles;
    else this.follow(reply.retVal.commandId, name, cycles);
    this.ctx.changed('paths');
    return reply;
  }

  follow(commandId, path, cycles = null) {
    this.run = { commandId, path, phase: 'running', cycles, cycle: 1, reached: new Map() };   // tag key -> name
    if (!this.paths.has(path)) {
      this.paths.set(path, { frame: '', motionType: '', tags: [], length: null, source: 'seen running' });
      this.refresh().then(() => this.readIfListed(path));
    } else this.readIfListed(path);
    this.ctx.changed('paths');
  }

  // The points of a path the device lists and the page does not know whole: its tags count.
  readIfListed(name) {
    const path = this.paths.get(name);
    return path?.source === STORED && !this.whole(name) ? this.read(name) : null;
  }

  // A landscape.v1.Event: a PathMove started by any client (its point name is the path's), the
  // tags it reaches and its end. A tag whose index is not past the last one reached starts
  // the path's next cycle.
  event(event) {
    const c = event.command;
    if (!c || c.command !== 'PathMove') return;
    if (c.phase === 'PHASE_STARTED' && this.run?.commandId !== c.commandId) this.follow(c.commandId, c.pointName);
    const run = this.run;
    if (c.commandId !== run?.commandId) return;
    if (c.phase === 'PHASE_TAG_REACHED') {
      const key = tagKey(c);
      if (run.reached.has(key)) { run.cycle += 1; run.reached.clear(); }
      run.reached.set(key, c.tagName);
    } else {
      run.phase = RUNNING.has(c.phase) ? 'running' : phaseWord(c.phase);
    }
    this.ctx.changed('paths');
  }

  // The tags of a path that raise events (the named ones), when the page knows every point.
  namedTags(name) {
    if (!this.whole(name)) return null;
    return this.paths.get(name).tags.filter((tag) => tag.tagName);
  }

  // "run 12 of tour: moving, cycle 2 of 3, 1/4 tags reached".
  progress(run = this.run) {
    const named = this.namedTags(run.path);
    const cycles = run.cycles > 1 ? `cycle ${run.cycle} of ${run.cycles}, ` : run.cycle > 1 ? `cycle ${run.cycle}, ` : '';
    const count = named ? `${run.reached.size}/${named.length}` : `${run.reached.size}`;
    return `run ${run.commandId} of ${run.path}: ${run.phase}, ${cycles}${count} tags reached`;
  }
}
