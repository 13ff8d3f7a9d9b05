// The device's units (landscape.v1.Units, by enum name) and conversions to and from meters and
// radians, the units of the URDF and of the state stream the backend asks for.

const METERS_PER = {
  LINEAR_UNIT_METERS: 1, LINEAR_UNIT_MILLIMETERS: 0.001, LINEAR_UNIT_CENTIMETERS: 0.01,
  LINEAR_UNIT_INCHES: 0.0254, LINEAR_UNIT_FEET: 0.3048,
};
const RADIANS_PER = { ANGULAR_UNIT_RADIANS: 1, ANGULAR_UNIT_DEGREES: Math.PI / 180 };
const SYMBOL = {
  LINEAR_UNIT_METERS: 'm', LINEAR_UNIT_MILLIMETERS: 'mm', LINEAR_UNIT_CENTIMETERS: 'cm',
  LINEAR_UNIT_INCHES: 'in', LINEAR_UNIT_FEET: 'ft', ANGULAR_UNIT_RADIANS: 'rad', ANGULAR_UNIT_DEGREES: '°',
};

export const SI = { linear: 'LINEAR_UNIT_METERS', angular: 'ANGULAR_UNIT_RADIANS' };

export function symbol(unit) { return SYMBOL[unit] || '?'; }

// A length or an angle from `units` to SI (kind 'linear' or 'angular').
export function toSI(value, kind, units) {
  const factor = kind === 'linear' ? METERS_PER[units.linear] : RADIANS_PER[units.angular];
  return value * (factor || 1);
}

export function fromSI(value, kind, units) {
  const factor = kind === 'linear' ? METERS_PER[units.linear] : RADIANS_PER[units.angular];
  return value / (factor || 1);
}

// A pose {x, y, z, roll, pitch, yaw} from `units` to SI.
export function poseToSI(pose, units) {
  return {
    x: toSI(pose.x, 'linear', units), y: toSI(pose.y, 'linear', units), z: toSI(pose.z, 'linear', units),
    roll: toSI(pose.roll, 'angular', units), pitch: toSI(pose.pitch, 'angular', units), yaw: toSI(pose.yaw, 'angular', units),
  };
}

export function fmt(value, digits = 3) {
  return Number.isFinite(value) ? value.toFixed(digits) : '–';
}

// Tick labels with as many decimals as the step between ticks needs, and no more: a step
// of 0.25 shows 0.25, 0.5, ...; a step of 2 shows 0, 2, 4.
export function tickText(value, step) {
  let decimals = Math.min(6, Math.max(0, Math.ceil(-Math.log10(step) - 1e-9)));
  if (decimals < 6 && Math.abs(step * 10 ** decimals - Math.round(step * 10 ** decimals)) > 1e-6) decimals += 1;
  const text = value.toFixed(decimals);
  return /^-0(\.0*)?$/.test(text) ? text.slice(1) : text;
}
