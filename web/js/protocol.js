// Messages of docs/protocol.md as seen by the browser: the envelope, the binary camera frame, and
// pose conversions. Pure functions (no DOM, no three.js), so Node's test runner checks them too.

export const kProtocolVersion = 1;
export const kBinaryMagic = 'TSB1';
export const kBinaryHeaderBytes = 32;
export const kBinaryTypeCameraFrame = 10;
export const kFormatGray8 = 1;
export const kFormatRgb8 = 2;

// Parses a binary frame (protocol.md, "Binary frames"). Returns {type, format, camera, seq, width,
// height, stamp_s, pixels} or throws an Error naming the field that is wrong.
export function parseBinaryFrame(buffer) {
  if (!(buffer instanceof ArrayBuffer)) throw new Error('binary frame: not an ArrayBuffer');
  if (buffer.byteLength < kBinaryHeaderBytes) {
    throw new Error(`binary frame: ${buffer.byteLength} bytes, the header alone is ${kBinaryHeaderBytes}`);
  }
  const view = new DataView(buffer);
  const magic = String.fromCharCode(view.getUint8(0), view.getUint8(1), view.getUint8(2), view.getUint8(3));
  if (magic !== kBinaryMagic) throw new Error(`binary frame: magic is "${magic}", expected "${kBinaryMagic}"`);
  const type = view.getUint8(4);
  if (type !== kBinaryTypeCameraFrame) throw new Error(`binary frame: type ${type}, expected ${kBinaryTypeCameraFrame} (camera_frame)`);
  const format = view.getUint8(5);
  const bpp = format === kFormatGray8 ? 1 : format === kFormatRgb8 ? 3 : 0;
  if (!bpp) throw new Error(`binary frame: format ${format}, expected 1 (gray8) or 2 (rgb8)`);
  const camera = view.getUint16(6, true);
  const seq = Number(view.getBigUint64(8, true));
  const width = view.getUint32(16, true);
  const height = view.getUint32(20, true);
  const stamp_s = view.getFloat64(24, true);
  if (width < 1 || width > 16384 || height < 1 || height > 16384) {
    throw new Error(`binary frame: size ${width}x${height}, expected 1..16384 each`);
  }
  if (!Number.isFinite(stamp_s) || stamp_s < 0) throw new Error(`binary frame: stamp_s ${stamp_s}, expected finite >= 0`);
  const expected = kBinaryHeaderBytes + width * height * bpp;
  if (buffer.byteLength !== expected) {
    throw new Error(`binary frame: ${buffer.byteLength} bytes, expected ${expected} for ${width}x${height}x${bpp}`);
  }
  return { type, format, camera, seq, width, height, stamp_s,
           pixels: new Uint8Array(buffer, kBinaryHeaderBytes) };
}

// Fills an RGBA buffer (ImageData.data) from a parsed frame.
export function frameToRgba(frame, rgba) {
  const n = frame.width * frame.height;
  const px = frame.pixels;
  if (frame.format === kFormatGray8) {
    for (let i = 0, j = 0; i < n; ++i, j += 4) {
      const g = px[i];
      rgba[j] = g; rgba[j + 1] = g; rgba[j + 2] = g; rgba[j + 3] = 255;
    }
  } else {
    for (let i = 0, j = 0, k = 0; i < n; ++i, j += 4, k += 3) {
      rgba[j] = px[k]; rgba[j + 1] = px[k + 1]; rgba[j + 2] = px[k + 2]; rgba[j + 3] = 255;
    }
  }
}

// Outgoing sequence numbers: 1 for the first message on a connection, then +1 (protocol.md).
export class Sequencer {
  constructor() { this.next = 1; }
  take() { return this.next++; }
}

// Incoming sequence check, mirroring what the server does: returns 'ok', 'gap' or 'duplicate'.
export class SeqTracker {
  constructor() { this.last = 0; this.gaps = 0; this.duplicates = 0; }
  accept(seq) {
    if (!Number.isSafeInteger(seq) || seq < 1) return 'invalid';
    if (seq <= this.last) { ++this.duplicates; return 'duplicate'; }
    const result = seq === this.last + 1 ? 'ok' : 'gap';
    if (result === 'gap') ++this.gaps;
    this.last = seq;
    return result;
  }
}

// Poses on the wire: {position: [x, y, z], quaternion_wxyz: [w, x, y, z]}.
export function isPose(p) {
  return p && Array.isArray(p.position) && p.position.length === 3 &&
         Array.isArray(p.quaternion_wxyz) && p.quaternion_wxyz.length === 4 &&
         p.position.every(Number.isFinite) && p.quaternion_wxyz.every(Number.isFinite);
}

export function makePose(position, quaternion_wxyz) {
  const q = normalizeQuat(quaternion_wxyz);
  return { position: [position[0], position[1], position[2]], quaternion_wxyz: q };
}

export function normalizeQuat(q) {
  const n = Math.hypot(q[0], q[1], q[2], q[3]);
  if (!(n > 0)) return [1, 0, 0, 0];
  return [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
}

// Rotates vector v by the unit quaternion q (wxyz).
export function rotate(q, v) {
  const [w, x, y, z] = q;
  // t = 2 q_vec × v; v' = v + w t + q_vec × t
  const tx = 2 * (y * v[2] - z * v[1]);
  const ty = 2 * (z * v[0] - x * v[2]);
  const tz = 2 * (x * v[1] - y * v[0]);
  return [v[0] + w * tx + (y * tz - z * ty),
          v[1] + w * ty + (z * tx - x * tz),
          v[2] + w * tz + (x * ty - y * tx)];
}

export function transformPoint(pose, p) {
  const r = rotate(pose.quaternion_wxyz, p);
  return [r[0] + pose.position[0], r[1] + pose.position[1], r[2] + pose.position[2]];
}

export function inversePose(pose) {
  const [w, x, y, z] = pose.quaternion_wxyz;
  const qi = [w, -x, -y, -z];
  const t = rotate(qi, pose.position);
  return { position: [-t[0], -t[1], -t[2]], quaternion_wxyz: qi };
}

// Yaw (rotation about world z) of a pose in radians, for display.
export function yawOf(q) {
  const [w, x, y, z] = q;
  return Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
}

export function formatMm(position) {
  return '(' + position.map((v) => (v * 1000).toFixed(1)).join(', ') + ') mm';
}
