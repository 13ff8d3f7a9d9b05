// Joint values that put the tool tip at a pose, for the ghost arm's preview of a Cartesian
// goal: damped least squares on the arm's own URDF kinematics, from the joints the arm has
// now, so the answer keeps the arm's present configuration (shoulder, elbow, wrist), as the
// device's configuration continuity does. The device plans the move itself; this is only
// the picture before it (the contract has no call that solves a pose without moving).
import * as THREE from 'three';

const MAX_STEPS = 200;
const DAMPING = 0.05;
const MAX_STEP_RAD = 0.2;
const DELTA = 1e-6;
const POSITION_TOLERANCE = 1e-5;   // m
const ANGLE_TOLERANCE = 1e-4;      // rad

// The 6-vector from pose a to pose b (matrices): position difference and rotation vector.
function error(a, b) {
  const pa = new THREE.Vector3().setFromMatrixPosition(a);
  const pb = new THREE.Vector3().setFromMatrixPosition(b);
  const qa = new THREE.Quaternion().setFromRotationMatrix(a);
  const qb = new THREE.Quaternion().setFromRotationMatrix(b);
  const turn = qb.multiply(qa.invert());
  if (turn.w < 0) turn.set(-turn.x, -turn.y, -turn.z, -turn.w);
  const sin = Math.hypot(turn.x, turn.y, turn.z);
  const angle = 2 * Math.atan2(sin, turn.w);
  const k = sin > 1e-12 ? angle / sin : 2;
  return [pb.x - pa.x, pb.y - pa.y, pb.z - pa.z, turn.x * k, turn.y * k, turn.z * k];
}

// x solving A x = b for a small dense A (Gaussian elimination with partial pivoting).
function solve(A, b) {
  const n = b.length;
  const m = A.map((row, i) => [...row, b[i]]);
  for (let c = 0; c < n; c += 1) {
    let pivot = c;
    for (let r = c + 1; r < n; r += 1) if (Math.abs(m[r][c]) > Math.abs(m[pivot][c])) pivot = r;
    [m[c], m[pivot]] = [m[pivot], m[c]];
    for (let r = c + 1; r < n; r += 1) {
      const f = m[r][c] / m[c][c];
      for (let k = c; k <= n; k += 1) m[r][k] -= f * m[c][k];
    }
  }
  const x = new Array(n).fill(0);
  for (let r = n - 1; r >= 0; r -= 1) {
    let sum = m[r][n];
    for (let k = r + 1; k < n; k += 1) sum -= m[r][k] * x[k];
    x[r] = sum / m[r][r];
  }
  return x;
}

// Joints (rad) putting tip(joints) (a Matrix4) at `target`, from `start`, within `limits`
// ([{lower, upper}]); null when no such joints are found.
export function solvePose(tip, target, start, limits) {
  let q = start.slice();
  for (let step = 0; step < MAX_STEPS; step += 1) {
    const now = tip(q);
    const e = error(now, target);
    if (Math.hypot(e[0], e[1], e[2]) < POSITION_TOLERANCE && Math.hypot(e[3], e[4], e[5]) < ANGLE_TOLERANCE) return q;
    // J (6 x n) by differences; dq = J^T (J J^T + damping^2 I)^-1 e.
    const J = q.map((_, j) => {
      const moved = q.slice();
      moved[j] += DELTA;
      return error(now, tip(moved)).map((v) => v / DELTA);
    });   // J[j] is column j
    const JJt = [0, 1, 2, 3, 4, 5].map((r) => [0, 1, 2, 3, 4, 5].map((c) => J.reduce((s, col) => s + col[r] * col[c], 0)
      + (r === c ? DAMPING ** 2 : 0)));
    const y = solve(JJt, e);
    let dq = J.map((col) => col.reduce((s, v, r) => s + v * y[r], 0));
    const largest = Math.max(...dq.map(Math.abs));
    if (largest > MAX_STEP_RAD) dq = dq.map((v) => (v * MAX_STEP_RAD) / largest);
    q = q.map((v, j) => Math.min(limits[j].upper, Math.max(limits[j].lower, v + dq[j])));
  }
  return null;
}
