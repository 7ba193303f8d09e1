// The camera model of docs/formats/camera.md (OpenCV's pinhole with k1 k2 p1 p2 k3), used to draw
// recognitions as wireframes over the camera image (paper §4.3, Figure 6). Pure functions.
import { inversePose, transformPoint, rotate } from './protocol.js';

// Accepts a camera entry of the scene format ({fx, fy, cx, cy, k1.., position, quaternion_wxyz})
// or one whose pose is nested as world_T_camera. Returns a normalized camera or throws.
export function normalizeCamera(c) {
  if (!c || typeof c !== 'object') throw new Error('camera: not an object');
  const pose = c.world_T_camera ?? { position: c.position, quaternion_wxyz: c.quaternion_wxyz };
  for (const k of ['fx', 'fy', 'cx', 'cy', 'width', 'height']) {
    if (!Number.isFinite(c[k])) throw new Error(`camera.${k}: missing or not a number`);
  }
  if (!pose || !Array.isArray(pose.position) || !Array.isArray(pose.quaternion_wxyz)) {
    throw new Error('camera: pose (position, quaternion_wxyz or world_T_camera) missing');
  }
  return {
    name: c.name ?? 'camera', width: c.width, height: c.height,
    fx: c.fx, fy: c.fy, cx: c.cx, cy: c.cy,
    k1: c.k1 ?? 0, k2: c.k2 ?? 0, p1: c.p1 ?? 0, p2: c.p2 ?? 0, k3: c.k3 ?? 0,
    world_T_camera: pose, camera_T_world: inversePose(pose),
  };
}

// Projects a world point to pixel coordinates [u, v], or null when it is behind the camera or
// beyond the fold of the distortion polynomial (where the model is not one-to-one).
export function projectPoint(cam, p_in_world) {
  const p = transformPoint(cam.camera_T_world, p_in_world);
  if (p[2] <= 1e-6) return null;
  const x = p[0] / p[2];
  const y = p[1] / p[2];
  const r2 = x * x + y * y;
  // d/dr of r·radial(r) must stay positive
  if (1 + 3 * cam.k1 * r2 + 5 * cam.k2 * r2 * r2 + 7 * cam.k3 * r2 * r2 * r2 <= 0) return null;
  const radial = 1 + cam.k1 * r2 + cam.k2 * r2 * r2 + cam.k3 * r2 * r2 * r2;
  const xd = x * radial + 2 * cam.p1 * x * y + cam.p2 * (r2 + 2 * x * x);
  const yd = y * radial + cam.p1 * (r2 + 2 * y * y) + 2 * cam.p2 * x * y;
  return [cam.fx * xd + cam.cx, cam.fy * yd + cam.cy];
}

// The 12 edges of a box of full size [sx, sy, sz] centred at its frame's origin, in world.
export function boxEdgesInWorld(world_T_box, size) {
  const h = size.map((s) => s / 2);
  const corners = [];
  for (let i = 0; i < 8; ++i) {
    corners.push(transformPoint(world_T_box, [(i & 1 ? 1 : -1) * h[0], (i & 2 ? 1 : -1) * h[1], (i & 4 ? 1 : -1) * h[2]]));
  }
  const edges = [];
  for (let i = 0; i < 8; ++i) {
    for (const bit of [1, 2, 4]) {
      if (!(i & bit)) edges.push([corners[i], corners[i | bit]]);
    }
  }
  return edges;
}

// Projects edges as polylines (distortion bends straight edges), split where points are not
// projectable. Returns a list of polylines, each a list of [u, v].
export function projectEdges(cam, edges, subdivisions = 8) {
  const lines = [];
  for (const [a, b] of edges) {
    let current = [];
    for (let i = 0; i <= subdivisions; ++i) {
      const t = i / subdivisions;
      const uv = projectPoint(cam, [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])]);
      if (uv) current.push(uv);
      else if (current.length) { if (current.length > 1) lines.push(current); current = []; }
    }
    if (current.length > 1) lines.push(current);
  }
  return lines;
}

// Optical axis in world, for tests.
export function cameraAxisInWorld(cam) { return rotate(cam.world_T_camera.quaternion_wxyz, [0, 0, 1]); }
