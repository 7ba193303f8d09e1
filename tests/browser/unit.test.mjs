// Unit tests of the browser UI's pure modules (no browser needed): the binary camera frame of
// docs/protocol.md, sequence tracking, pose algebra, the OpenCV camera model used for the
// recognition overlays, and the dragger's ray-plane drag (paper §5, Figure 7).
// Run: node --test tests/browser/unit.test.mjs
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { fileURLToPath } from 'node:url';
import path from 'node:path';
import { parseBinaryFrame, frameToRgba, SeqTracker, rotate, transformPoint, inversePose, yawOf }
  from '../../web/js/protocol.js';
import { normalizeCamera, projectPoint, boxEdgesInWorld, projectEdges } from '../../web/js/camera_model.js';
import { rayPlane, PlaneDrag } from '../../web/js/drag_math.js';

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..');

function makeFrame({ width = 4, height = 3, format = 1, seq = 7, stamp = 1.5, magic = 'TSB1', type = 10, extra = 0 } = {}) {
  const bpp = format === 2 ? 3 : 1;
  const buf = new ArrayBuffer(32 + width * height * bpp + extra);
  const v = new DataView(buf);
  for (let i = 0; i < 4; ++i) v.setUint8(i, magic.charCodeAt(i));
  v.setUint8(4, type); v.setUint8(5, format); v.setUint16(6, 0, true);
  v.setBigUint64(8, BigInt(seq), true);
  v.setUint32(16, width, true); v.setUint32(20, height, true);
  v.setFloat64(24, stamp, true);
  const px = new Uint8Array(buf, 32);
  for (let i = 0; i < px.length; ++i) px[i] = i % 256;
  return buf;
}

test('binary frame: a gray8 frame parses and converts to RGBA', () => {
  const f = parseBinaryFrame(makeFrame());
  assert.equal(f.width, 4); assert.equal(f.height, 3); assert.equal(f.seq, 7); assert.equal(f.stamp_s, 1.5);
  const rgba = new Uint8ClampedArray(4 * 12);
  frameToRgba(f, rgba);
  assert.deepEqual([...rgba.slice(20, 24)], [5, 5, 5, 255]);
});

test('binary frame: rgb8 converts channel by channel', () => {
  const f = parseBinaryFrame(makeFrame({ format: 2, width: 2, height: 1 }));
  const rgba = new Uint8ClampedArray(8);
  frameToRgba(f, rgba);
  assert.deepEqual([...rgba], [0, 1, 2, 255, 3, 4, 5, 255]);
});

test('binary frame: wrong magic, type, format, size and stamp are refused with the field named', () => {
  assert.throws(() => parseBinaryFrame(makeFrame({ magic: 'XSB1' })), /magic/);
  assert.throws(() => parseBinaryFrame(makeFrame({ type: 3 })), /type 3/);
  assert.throws(() => parseBinaryFrame(makeFrame({ format: 9 })), /format 9/);
  assert.throws(() => parseBinaryFrame(makeFrame({ extra: 1 })), /expected 44/);
  assert.throws(() => parseBinaryFrame(makeFrame({ stamp: -1 })), /stamp_s/);
  assert.throws(() => parseBinaryFrame(new ArrayBuffer(10)), /header/);
});

test('sequence tracker: gaps and duplicates as the protocol defines them', () => {
  const t = new SeqTracker();
  assert.equal(t.accept(1), 'ok');
  assert.equal(t.accept(2), 'ok');
  assert.equal(t.accept(5), 'gap');
  assert.equal(t.accept(5), 'duplicate');
  assert.equal(t.accept(3), 'duplicate');
  assert.equal(t.accept(6), 'ok');
  assert.equal(t.gaps, 1); assert.equal(t.duplicates, 2);
});

test('poses: rotation, transform and inverse agree', () => {
  const s = Math.SQRT1_2;
  const pose = { position: [1, 2, 3], quaternion_wxyz: [s, 0, 0, s] };   // 90° about z
  const r = rotate(pose.quaternion_wxyz, [1, 0, 0]);
  assert.ok(Math.abs(r[0]) < 1e-12 && Math.abs(r[1] - 1) < 1e-12);
  const p = transformPoint(pose, [0.5, -0.25, 1]);
  const back = transformPoint(inversePose(pose), p);
  back.forEach((v, i) => assert.ok(Math.abs(v - [0.5, -0.25, 1][i]) < 1e-12));
  assert.ok(Math.abs(yawOf(pose.quaternion_wxyz) - Math.PI / 2) < 1e-12);
});

test('camera model: the scene camera projects its own axis to the principal point and a table point into the image', () => {
  const scene = JSON.parse(readFileSync(path.join(root, 'scenes/puzzle.json'), 'utf8'));
  const cam = normalizeCamera(scene.cameras[0]);
  const c = cam.world_T_camera.position;
  const axis = rotate(cam.world_T_camera.quaternion_wxyz, [0, 0, 1]);
  const uv = projectPoint(cam, [c[0] + axis[0], c[1] + axis[1], c[2] + axis[2]]);
  assert.ok(Math.abs(uv[0] - cam.cx) < 1e-9 && Math.abs(uv[1] - cam.cy) < 1e-9);
  const behind = projectPoint(cam, [c[0] - axis[0], c[1] - axis[1], c[2] - axis[2]]);
  assert.equal(behind, null);
  // the cube of the puzzle scene is in view
  const cube = scene.objects.find((o) => o.name === 'cube');
  const lines = projectEdges(cam, boxEdgesInWorld(cube.pose, cube.shape.box));
  assert.ok(lines.length >= 12);
  for (const line of lines) for (const [u, v] of line) assert.ok(u > 0 && u < cam.width && v > 0 && v < cam.height, `${u},${v}`);
});

test('camera model: radial distortion moves off-axis points as OpenCV does', () => {
  const cam = normalizeCamera({ width: 100, height: 100, fx: 100, fy: 100, cx: 50, cy: 50, k1: -0.2,
    position: [0, 0, 0], quaternion_wxyz: [1, 0, 0, 0] });
  const [u] = projectPoint(cam, [0.3, 0, 1]);   // r² = 0.09: x_d = 0.3 (1 - 0.018)
  assert.ok(Math.abs(u - (50 + 100 * 0.3 * (1 - 0.2 * 0.09))) < 1e-9);
});

test('box edges: 12 edges of the right lengths', () => {
  const edges = boxEdgesInWorld({ position: [0, 0, 0], quaternion_wxyz: [1, 0, 0, 0] }, [1, 2, 3]);
  assert.equal(edges.length, 12);
  const lengths = edges.map(([a, b]) => Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2])).sort();
  assert.deepEqual(lengths, [1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3]);
});

test('dragger: a ray meets the face plane, and the dragger moves in that plane only', () => {
  assert.deepEqual(rayPlane([0, 0, 1], [0, 0, -1], [0, 0, 0], [0, 0, 1]), [0, 0, 0]);
  assert.equal(rayPlane([0, 0, 1], [1, 0, 0], [0, 0, 0], [0, 0, 1]), null);   // parallel
  assert.equal(rayPlane([0, 0, 1], [0, 0, 1], [0, 0, 0], [0, 0, 1]), null);   // pointing away
  // grab the top face (z = 0.05) at (0.01, 0, 0.05) of a dragger at (0, 0, 0.02)
  const drag = new PlaneDrag([0.01, 0, 0.05], [0, 0, 1], [0, 0, 0.02]);
  const eye = [0.3, -0.5, 0.5];
  const target = [-0.09, -0.06, 0.05];
  const dir = target.map((v, i) => v - eye[i]);
  const p = drag.update(eye, dir);
  assert.ok(Math.abs(p[0] - (-0.1)) < 1e-12 && Math.abs(p[1] - (-0.06)) < 1e-12 && Math.abs(p[2] - 0.02) < 1e-12);
  // a grazing ray is clamped, not thrown across the world
  const far = drag.update([0, 0, 0.0500001], [1, 0, -1e-6]);
  assert.ok(far === null || Math.hypot(far[0], far[1]) <= 0.5 + 1e-9);
});

// ---- the whole arm (web/js/kinematics.js): the robot table's modified DH, as src/robot ----------

import { armFrames, armSegments, checkKinematics, toPose } from '../../web/js/kinematics.js';

const crs = JSON.parse(readFileSync(path.join(root, 'robots/crs_a465.json'), 'utf8'));
const atOrigin = { position: [0, 0, 0], quaternion_wxyz: [1, 0, 0, 0] };

test('arm: at q = 0 the upper arm is vertical and the forearm and tool point along base x (robots/crs_a465.json)', () => {
  const f = armFrames(checkKinematics(crs), atOrigin, [0, 0, 0, 0, 0, 0]);
  assert.equal(f.length, 8);   // base, six link frames, tool
  const close = (a, b) => a.every((v, i) => Math.abs(v - b[i]) < 1e-9);
  assert.ok(close(f[1].p, [0, 0, 0.33]), `shoulder ${f[1].p}`);        // d1
  assert.ok(close(f[3].p, [0, 0, 0.635]), `elbow ${f[3].p}`);          // + a2 up
  assert.ok(close(f[6].p, [0.406, 0, 0.635]), `flange ${f[6].p}`);     // + d4 + d6 along x
  assert.ok(close(f[7].p, [0.536, 0, 0.635]), `tool ${f[7].p}`);       // + 130 mm of gripper
  // drawn links: base-shoulder, upper arm, forearm, wrist-flange, flange-tool (zero lengths dropped)
  assert.equal(armSegments(f).length, 5);
});

test('arm: the ready pose points the tool down, and the base placement moves the whole arm', () => {
  const base = { position: [0, -0.36, 0], quaternion_wxyz: [Math.SQRT1_2, 0, 0, Math.SQRT1_2] };   // turned 90° about z
  const tool = toPose(armFrames(crs, base, crs.ready_rad)[7]);
  const local = toPose(armFrames(crs, atOrigin, crs.ready_rad)[7]);
  // turned by 90°: local (x, y) -> world (-y, x), shifted by the base
  assert.ok(Math.abs(tool.position[0] - (-local.position[1])) < 1e-9);
  assert.ok(Math.abs(tool.position[1] - (local.position[0] - 0.36)) < 1e-9);
  assert.ok(Math.abs(tool.position[2] - local.position[2]) < 1e-9);
  // tool z (the approach direction) points down
  const [w, x, y, z] = tool.quaternion_wxyz;
  const approachZ = 1 - 2 * (x * x + y * y);
  assert.ok(approachZ < -0.999, `tool z axis has world z ${approachZ}`);
});

test('arm: a table that is not six modified-DH joints is refused naming the field', () => {
  assert.throws(() => checkKinematics({ ...crs, joints: crs.joints.slice(0, 5) }), /kinematics\.joints: must list 6/);
  assert.throws(() => checkKinematics({ ...crs, dh_convention: 'standard' }), /dh_convention/);
  const bad = structuredClone(crs); bad.joints[2].a_m = 'x';
  assert.throws(() => checkKinematics(bad), /joints\[2\]\.a_m/);
});
