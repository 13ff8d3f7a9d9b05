// What the page says to people: the contract's enum names and the device's state strings as
// words ("resting", "stopped on command", "m"), and a refused call's status as a sentence
// with the machine's codes kept apart, in small print, for whoever reports it.
import { typeOf } from './link.js';

const STATES = {
  DEVICE_STATE_IDLE: 'idle', DEVICE_STATE_UNLOCKED: 'unlocked', DEVICE_STATE_INACTIVE: 'inactive',
  DEVICE_STATE_RESTING: 'resting', DEVICE_STATE_MOVING: 'moving', DEVICE_STATE_PAUSED: 'paused',
  DEVICE_STATE_ERROR: 'error',
};
// getMotionControlState's strings (server/states.py) and the controller's modes.
const MOTION = {
  running_trajectory: 'running a trajectory', robot_paused: 'paused',
  robot_stopped_on_error: 'stopped on error', robot_stopped_on_command: 'stopped on command',
  robot_idle: 'idle', power_on: 'on', power_off: 'off', controller_error: 'controller error',
};
const PHASES = {
  PHASE_STARTED: 'started', PHASE_TAG_REACHED: 'tag reached', PHASE_PAUSED: 'paused',
  PHASE_RESUMED: 'resumed', PHASE_DONE: 'done', PHASE_FAILED: 'failed', PHASE_ABORTED: 'aborted',
};
const SEVERITIES = {
  ALARM_SEVERITY_INFO: 'info', ALARM_SEVERITY_WARNING: 'warning', ALARM_SEVERITY_ERROR: 'error',
  ALARM_SEVERITY_CRITICAL: 'critical',
};
export const UNIT_WORDS = {
  LINEAR_UNIT_METERS: 'm', LINEAR_UNIT_MILLIMETERS: 'mm', LINEAR_UNIT_CENTIMETERS: 'cm',
  LINEAR_UNIT_INCHES: 'in', LINEAR_UNIT_FEET: 'ft', ANGULAR_UNIT_RADIANS: 'rad', ANGULAR_UNIT_DEGREES: '°',
};
const FRAMES = {
  REFERENCE_FRAME_JOINT_FRAME: 'joints', REFERENCE_FRAME_BASE_CARTESIAN_FRAME: 'base',
  REFERENCE_FRAME_WORLD_CARTESIAN_FRAME: 'world', REFERENCE_FRAME_TOOL_FRAME: 'tool',
};
const MANUAL = { off: 'off', teachpendant: 'teach pendant', spaceball: 'spaceball' };

// gRPC codes as what they mean to the person who pressed the button.
const CODES = ['OK', 'CANCELLED', 'UNKNOWN', 'INVALID_ARGUMENT', 'DEADLINE_EXCEEDED', 'NOT_FOUND',
  'ALREADY_EXISTS', 'PERMISSION_DENIED', 'RESOURCE_EXHAUSTED', 'FAILED_PRECONDITION', 'ABORTED',
  'OUT_OF_RANGE', 'UNIMPLEMENTED', 'INTERNAL', 'UNAVAILABLE', 'DATA_LOSS', 'UNAUTHENTICATED'];
const CODE_WORDS = {
  1: 'cancelled', 2: 'failed', 3: 'not valid', 4: 'no answer in time', 5: 'not found',
  6: 'already there', 7: 'not allowed', 8: 'too much at once', 9: 'not in this state',
  10: 'interrupted', 11: 'out of range', 12: 'not available on this device', 13: 'failed inside',
  14: 'not reachable', 15: 'data lost', 16: 'not signed in',
};
// gRPC's asyncio client may put this in place of the device's own status after a stall
// (grpc/grpc#36066): it names no cause, so the page says what it does know.
const GARBLED = /Internal error from Core/i;
const GARBLED_SAYS = 'the connection to the device broke off (gRPC gave no reason)';

const lookup = (table, name, prefix) => table[name] ?? ((name || '').replace(prefix, '').toLowerCase().replaceAll('_', ' ') || '–');

export const stateWord = (name) => lookup(STATES, name, 'DEVICE_STATE_');
export const motionWord = (text) => lookup(MOTION, text, '');
export const phaseWord = (name) => lookup(PHASES, name, 'PHASE_');
export const severityWord = (name) => lookup(SEVERITIES, name, 'ALARM_SEVERITY_');
export const frameWord = (name) => lookup(FRAMES, name, 'REFERENCE_FRAME_');
export const manualWord = (text) => lookup(MANUAL, text, '');
export const unitWord = (name) => UNIT_WORDS[name] || '?';

// gRPC's words for a device server that is not there, and what they mean.
const ADDRESS = /(?:\d+\.){3}\d+:\d+|\[[^\]]+\]:\d+/;
function transport(text) {
  if (/failed to connect to all addresses/i.test(text)) {
    const at = ADDRESS.exec(text);
    return /Connection refused/i.test(text)
      ? `the device server${at ? ` at ${at[0]}` : ''} refuses connections (it is not running)`
      : 'the device server cannot be reached';
  }
  return /^(Socket closed|Connection reset by peer|Broken pipe)$/i.test(text) ? 'the connection to the device server closed' : '';
}

// A message the device or gRPC wrote, readable: a garbled or transport status said plainly.
export function readable(message) {
  const text = message || '';
  return transport(text) || (GARBLED.test(text) ? text.replace(GARBLED, GARBLED_SAYS) : text);
}

// A google.rpc.Status as {text, codes}: what happened in words (the server's own message
// first), and the codes an engineer looks for ("OUT_OF_RANGE PARAM_OUT_OF_RANGE ret_code -3").
export function explain(status) {
  const info = (status.details || []).find((d) => typeOf(d) === 'google.rpc.ErrorInfo');
  const codes = [CODES[status.code] || `code ${status.code}`];
  if (info) {
    codes.push(info.reason);
    if (info.metadata && info.metadata.ret_code !== undefined) codes.push(`ret_code ${info.metadata.ret_code}`);
  }
  const message = readable(status.message);
  return { text: message || CODE_WORDS[status.code] || 'refused', codes: codes.join(' ') };
}

// One line: the words, then the codes.
export function explainLine(status) {
  const { text, codes } = explain(status);
  return `${text} [${codes}]`;
}

// "3.2 s", "4 min", "1 h 5 min": how long, for people.
export function duration(ms) {
  const s = ms / 1000;
  if (s < 60) return `${s < 10 ? s.toFixed(1) : Math.round(s)} s`;
  const min = Math.round(s / 60);
  return min < 60 ? `${min} min` : `${Math.floor(min / 60)} h ${min % 60} min`;
}

export function clock(ms) {
  return new Date(ms).toLocaleTimeString();
}

// The 3D view's line: the arm, and the cell as its device describes it.
export function describeCell(robotType, cell) {
  const world = cell?.refused ? `no cell description: ${explainLine(cell.refused)}` : `cell “${cell?.cellName || '…'}”`;
  return `${robotType || '…'} in ${world}`;
}
