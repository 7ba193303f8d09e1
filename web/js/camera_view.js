// The camera image window (paper §3.2, §4.3, Figure 6): the work site's live image with the
// recognitions drawn over it as wireframes, projected with the calibrated camera model.
import { frameToRgba } from './protocol.js';
import { normalizeCamera, boxEdgesInWorld, projectEdges } from './camera_model.js';
import { transformPoint, rotate } from './protocol.js';

export function scoreColor(score) {
  if (score >= 0.7) return '#3ddc6a';
  if (score >= 0.4) return '#ffd23f';
  return '#ff5a5a';
}

// World edges of a model shape placed at world_T_object (boxes and parts of boxes; a convex
// hull is drawn by its vertices' bounding box, which is what a wireframe of it needs at a glance).
export function shapeEdgesInWorld(shape, world_T_object) {
  if (shape.box) return boxEdgesInWorld(world_T_object, shape.box);
  if (shape.parts) {
    const out = [];
    for (const part of shape.parts) {
      const q = world_T_object.quaternion_wxyz;
      const pq = part.pose.quaternion_wxyz;
      // world_T_part = world_T_object * object_T_part
      const quat = [
        q[0] * pq[0] - q[1] * pq[1] - q[2] * pq[2] - q[3] * pq[3],
        q[0] * pq[1] + q[1] * pq[0] + q[2] * pq[3] - q[3] * pq[2],
        q[0] * pq[2] - q[1] * pq[3] + q[2] * pq[0] + q[3] * pq[1],
        q[0] * pq[3] + q[1] * pq[2] - q[2] * pq[1] + q[3] * pq[0],
      ];
      out.push(...shapeEdgesInWorld(part.shape, { position: transformPoint(world_T_object, part.pose.position), quaternion_wxyz: quat }));
    }
    return out;
  }
  if (shape.convex) {
    const v = shape.convex.vertices;
    const lo = [0, 1, 2].map((k) => Math.min(...v.map((p) => p[k])));
    const hi = [0, 1, 2].map((k) => Math.max(...v.map((p) => p[k])));
    const c = [0, 1, 2].map((k) => (lo[k] + hi[k]) / 2);
    const r = rotate(world_T_object.quaternion_wxyz, c);
    return boxEdgesInWorld({ position: [0, 1, 2].map((k) => world_T_object.position[k] + r[k]), quaternion_wxyz: world_T_object.quaternion_wxyz },
      [0, 1, 2].map((k) => hi[k] - lo[k]));
  }
  return [];
}

export class CameraView {
  constructor(canvas, info) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.info = info;
    this.frame = null;
    this.image = null;
    this.frames = 0;
    this.recognitions = null;
    this.cameras = [];
    this.models = new Map();
    this.hover = -1;
    this.overlaysDrawn = 0;
    this.lastFrameWall_s = null;
    this.rate_hz = 0;
    this.pending = false;
    this.drawEmpty('waiting for the first camera image…');
  }

  setCameras(list) {
    this.cameras = [];
    for (const c of list ?? []) {
      try { this.cameras.push(normalizeCamera(c)); } catch (e) { this.cameras.push(null); console.warn(e); }
    }
    this.schedule();
  }

  setModels(list) {
    this.models = new Map((list ?? []).map((m) => [m.name, m.shape]));
    this.schedule();
  }

  setFrame(frame) {
    // images per second over the last 2 s (frames can arrive in bursts)
    const now = performance.now() / 1000;
    this.arrivals = (this.arrivals ?? []).filter((t) => now - t < 2);
    this.arrivals.push(now);
    const span = now - this.arrivals[0];
    this.rate_hz = this.arrivals.length > 1 && span > 0 ? (this.arrivals.length - 1) / span : 0;
    ++this.frames;
    if (this.canvas.width !== frame.width || this.canvas.height !== frame.height) {
      this.canvas.width = frame.width;
      this.canvas.height = frame.height;
      this.image = null;
    }
    if (!this.image) this.image = this.ctx.createImageData(frame.width, frame.height);
    frameToRgba(frame, this.image.data);
    this.frame = frame;
    this.schedule();
  }

  setRecognitions(msg) { this.recognitions = msg; this.schedule(); }

  setHover(i) { if (i !== this.hover) { this.hover = i; this.schedule(); } }

  schedule() {
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(() => { this.pending = false; this.draw(); });
  }

  drawEmpty(text) {
    const { ctx, canvas } = this;
    ctx.fillStyle = '#111';
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    ctx.fillStyle = '#aaa';
    ctx.font = '20px system-ui, sans-serif';
    ctx.textAlign = 'center';
    ctx.fillText(text, canvas.width / 2, canvas.height / 2);
    ctx.textAlign = 'left';
  }

  draw() {
    if (!this.frame) { this.drawEmpty('waiting for the first camera image…'); return; }
    const { ctx } = this;
    ctx.putImageData(this.image, 0, 0);
    this.overlaysDrawn = 0;
    const r = this.recognitions;
    const cam = r ? this.cameras[r.camera] : null;
    if (r && cam) {
      // the image may be sent at another resolution than the calibration
      const sx = this.canvas.width / cam.width;
      const sy = this.canvas.height / cam.height;
      r.objects.forEach((o, i) => {
        const shape = this.models.get(o.model);
        if (!shape) return;
        const lines = projectEdges(cam, shapeEdgesInWorld(shape, o.world_T_object));
        const hovered = i === this.hover;
        ctx.strokeStyle = hovered ? '#4fc3ff' : scoreColor(o.score);
        ctx.lineWidth = hovered ? 3 : 1.6;
        let minU = Infinity, minV = Infinity;
        for (const line of lines) {
          ctx.beginPath();
          line.forEach(([u, v], k) => {
            if (k === 0) ctx.moveTo(u * sx, v * sy); else ctx.lineTo(u * sx, v * sy);
            minU = Math.min(minU, u * sx); minV = Math.min(minV, v * sy);
          });
          ctx.stroke();
        }
        if (lines.length) {
          ++this.overlaysDrawn;
          ctx.font = '13px system-ui, sans-serif';
          const label = `${i}: ${o.model} ${(o.score * 100).toFixed(0)}%`;
          const w = ctx.measureText(label).width + 6;
          ctx.fillStyle = 'rgba(0,0,0,.6)';
          ctx.fillRect(minU, Math.max(0, minV - 18), w, 16);
          ctx.fillStyle = hovered ? '#4fc3ff' : scoreColor(o.score);
          ctx.fillText(label, minU + 3, Math.max(12, minV - 5));
        }
      });
    }
    const f = this.frame;
    this.info.textContent = `${f.width}×${f.height}, ${this.rate_hz.toFixed(1)} images/s` +
      (r ? `, ${r.objects.length} recognized` : '');
  }

  snapshot() {
    return { frames: this.frames, width: this.frame?.width ?? 0, height: this.frame?.height ?? 0,
             rate_hz: this.rate_hz, overlaysDrawn: this.overlaysDrawn };
  }
}
