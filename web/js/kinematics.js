// Forward kinematics of the robot table (docs/formats/robot.md: Craig's modified Denavit–Hartenberg
// parameters), for drawing the whole arm in the model view from the joint angles the work site
// streams (robot_state.joints_rad). The same steps as src/robot/kinematics.cc, so the tool frame
// drawn here is the one the work site reports (robot_state.world_T_tool). Pure functions.

// 3x3 matrices as row-major arrays of 9 numbers.
const kIdentity = [1, 0, 0, 0, 1, 0, 0, 0, 1];

function mul(A, B) {
  const C = new Array(9).fill(0);
  for (let i = 0; i < 3; ++i) {
    for (let j = 0; j < 3; ++j) {
      C[i * 3 + j] = A[i * 3] * B[j] + A[i * 3 + 1] * B[3 + j] + A[i * 3 + 2] * B[6 + j];
    }
  }
  return C;
}
const rotX = (a) => [1, 0, 0, 0, Math.cos(a), -Math.sin(a), 0, Math.sin(a), Math.cos(a)];
const rotZ = (a) => [Math.cos(a), -Math.sin(a), 0, Math.sin(a), Math.cos(a), 0, 0, 0, 1];
const col = (R, j) => [R[j], R[3 + j], R[6 + j]];

export function quatToMatrix(q) {
  const [w, x, y, z] = q;
  return [
    1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
    2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
    2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
  ];
}

export function matrixToQuat(R) {
  const [m00, m01, m02, m10, m11, m12, m20, m21, m22] = R;
  const tr = m00 + m11 + m22;
  let w, x, y, z;
  if (tr > 0) {
    const s = Math.sqrt(tr + 1) * 2;
    w = s / 4; x = (m21 - m12) / s; y = (m02 - m20) / s; z = (m10 - m01) / s;
  } else if (m00 > m11 && m00 > m22) {
    const s = Math.sqrt(1 + m00 - m11 - m22) * 2;
    w = (m21 - m12) / s; x = s / 4; y = (m01 + m10) / s; z = (m02 + m20) / s;
  } else if (m11 > m22) {
    const s = Math.sqrt(1 + m11 - m00 - m22) * 2;
    w = (m02 - m20) / s; x = (m01 + m10) / s; y = s / 4; z = (m12 + m21) / s;
  } else {
    const s = Math.sqrt(1 + m22 - m00 - m11) * 2;
    w = (m10 - m01) / s; x = (m02 + m20) / s; y = (m12 + m21) / s; z = s / 4;
  }
  const n = Math.hypot(w, x, y, z);
  return [w / n, x / n, y / n, z / n];
}

function compose(a, b) {  // a ∘ b for {R, p}
  const Rb = b.R;
  const pb = b.p;
  return {
    R: mul(a.R, Rb),
    p: [0, 1, 2].map((i) => a.p[i] + a.R[i * 3] * pb[0] + a.R[i * 3 + 1] * pb[1] + a.R[i * 3 + 2] * pb[2]),
  };
}

const fromPose = (pose) => ({ R: quatToMatrix(pose.quaternion_wxyz), p: pose.position.slice() });
export const toPose = (f) => ({ position: f.p.slice(), quaternion_wxyz: matrixToQuat(f.R) });

// Checks a kinematics table (world_state.robot.kinematics: the robot file) enough to draw it.
export function checkKinematics(k) {
  if (!k || typeof k !== 'object') throw new Error('kinematics: not an object');
  if (k.dh_convention !== undefined && k.dh_convention !== 'modified') {
    throw new Error(`kinematics.dh_convention: only "modified" is drawn, got "${k.dh_convention}"`);
  }
  if (!Array.isArray(k.joints) || k.joints.length !== 6) throw new Error('kinematics.joints: must list 6 joints');
  k.joints.forEach((j, i) => {
    for (const f of ['alpha_rad', 'a_m', 'd_m']) {
      if (!Number.isFinite(j[f])) throw new Error(`kinematics.joints[${i}].${f}: must be a number`);
    }
  });
  if (!k.flange_T_tool?.position || !k.flange_T_tool?.quaternion_wxyz) throw new Error('kinematics.flange_T_tool: missing');
  return k;
}

// World frames of the base (index 0), the six DH link frames (1..6, 6 = the flange) and the tool
// (7), as {R, p}. `world_T_base` is the robot's placement (world_state.robot.base).
export function armFrames(kinematics, world_T_base, joints_rad) {
  const base = fromPose(world_T_base);
  const frames = [base];
  let f = { R: kIdentity.slice(), p: [0, 0, 0] };
  kinematics.joints.forEach((j, i) => {
    const theta = joints_rad[i] + (j.theta_offset_rad ?? 0);
    const R = mul(mul(f.R, rotX(j.alpha_rad)), rotZ(theta));
    const x = col(f.R, 0);
    const z = col(R, 2);
    const p = [0, 1, 2].map((k) => f.p[k] + x[k] * j.a_m + z[k] * j.d_m);
    f = { R, p };
    frames.push(compose(base, f));
  });
  frames.push(compose(frames[6], fromPose(kinematics.flange_T_tool)));
  return frames;
}

// The arm's links as segments between successive frame origins (zero-length ones dropped):
// [{from, to}] in world, base to tool.
export function armSegments(frames) {
  const out = [];
  for (let i = 1; i < frames.length; ++i) {
    const a = frames[i - 1].p;
    const b = frames[i].p;
    if (Math.hypot(b[0] - a[0], b[1] - a[1], b[2] - a[2]) > 1e-6) out.push({ from: a.slice(), to: b.slice() });
  }
  return out;
}
