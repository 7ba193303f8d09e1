// Dragger geometry (paper §5, Figure 7): dragging on a face of the dragger box moves the dragger
// in that face's plane. A mouse ray is intersected with the plane through the grabbed point with
// the face's normal; the dragger moves by the grabbed point's displacement. Pure functions.

export function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
export function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
export function add(a, b) { return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]; }
export function scale(a, s) { return [a[0] * s, a[1] * s, a[2] * s]; }

// Where the ray origin + t·direction (t ≥ 0) meets the plane through `point` with `normal`, or
// null when the ray runs (nearly) parallel to the plane or points away from it.
export function rayPlane(origin, direction, point, normal, minCos = 1e-3) {
  const denom = dot(direction, normal);
  const len = Math.hypot(...direction) * Math.hypot(...normal);
  if (!(len > 0) || Math.abs(denom) < minCos * len) return null;
  const t = dot(sub(point, origin), normal) / denom;
  if (t < 0) return null;
  return add(origin, scale(direction, t));
}

// A drag in progress: the face plane (grabbed point, normal) and the dragger's start position.
// `maxStep_m` bounds the dragger's distance from its start, so a ray grazing the plane cannot
// throw the dragger across the world.
export class PlaneDrag {
  constructor(grabbedPoint, normal, draggerStart, maxStep_m = 0.5) {
    this.grabbed = grabbedPoint.slice();
    this.normal = normal.slice();
    this.start = draggerStart.slice();
    this.maxStep_m = maxStep_m;
  }
  // The dragger position for a mouse ray, or null to keep the last one.
  update(origin, direction) {
    const hit = rayPlane(origin, direction, this.grabbed, this.normal);
    if (!hit) return null;
    let d = sub(hit, this.grabbed);
    // keep the motion exactly in the plane (round-off)
    const n2 = dot(this.normal, this.normal);
    d = sub(d, scale(this.normal, dot(d, this.normal) / n2));
    const len = Math.hypot(...d);
    if (len > this.maxStep_m) d = scale(d, this.maxStep_m / len);
    return add(this.start, d);
  }
}
