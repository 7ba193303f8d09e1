// The model viewing window (paper §3.2, §5, Figures 1, 7, 12): the operator's world model in 3D
// with an orbit camera; click a block to select it (a gripper and a dragger box appear), drag a
// face of the dragger box to move the dragger in that face's plane, shift-click for capture
// objects, and the demonstrated, deformed and simplified paths as half-size ghost blocks.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { ConvexGeometry } from 'three/addons/geometries/ConvexGeometry.js';
import { PlaneDrag } from './drag_math.js';
import { checkKinematics, armFrames, armSegments, matrixToQuat } from './kinematics.js';

const kWoods = [0xd9a866, 0xc98f55, 0xe3bd84, 0xb97b45, 0xdcb07a, 0xc49a6c];
const kTableColor = 0xcfc8b8;
const kFrameColor = 0x7a4a25;
const kFixedColor = 0x9a8f80;
const kCaptureColor = 0x1c9bd6;
const kPathColors = { initial: 0xffffff, deformed: 0xf39c12, simplified: 0x27ae60 };
const kDraggerMargin_m = 0.014;
const kMaxGhosts = 400;

function poseToObject3D(obj, pose) {
  const p = pose.position;
  const q = pose.quaternion_wxyz;
  obj.position.set(p[0], p[1], p[2]);
  obj.quaternion.set(q[1], q[2], q[3], q[0]);
}

// three.js geometries for a scene shape (docs/formats/scene.md): [{geometry, pose|null}].
function shapeGeometries(shape) {
  if (shape.box) return [{ geometry: new THREE.BoxGeometry(shape.box[0], shape.box[1], shape.box[2]), pose: null }];
  if (shape.convex) {
    const pts = shape.convex.vertices.map((v) => new THREE.Vector3(v[0], v[1], v[2]));
    return [{ geometry: new ConvexGeometry(pts), pose: null }];
  }
  if (shape.parts) {
    const out = [];
    for (const part of shape.parts) {
      for (const g of shapeGeometries(part.shape)) {
        out.push({ geometry: g.geometry, pose: part.pose, inner: g.pose });
      }
    }
    return out;
  }
  throw new Error('shape: none of box, convex, parts');
}

// Axis-aligned bounds of a shape in its own frame: {min, max} as THREE.Vector3.
function shapeBounds(shape) {
  const box = new THREE.Box3();
  for (const g of shapeGeometries(shape)) {
    g.geometry.computeBoundingBox();
    const b = g.geometry.boundingBox.clone();
    if (g.pose) {
      const m = new THREE.Matrix4();
      const o = new THREE.Object3D();
      poseToObject3D(o, g.pose);
      o.updateMatrix();
      m.copy(o.matrix);
      b.applyMatrix4(m);
    }
    box.union(b);
    g.geometry.dispose();
  }
  return box;
}

export class ModelView {
  constructor(container, { onSelect, onCapture, onDrag, onHover }) {
    this.container = container;
    this.onSelect = onSelect;     // (name, fixed) on a plain click
    this.onCapture = onCapture;   // (name) on shift-click
    this.onDrag = onDrag;         // (phase, world_T_dragger) while dragging a face
    this.onHover = onHover ?? (() => {});
    this.objects = new Map();     // name -> {group, meshes, fixed, shape, size, pose, colorIndex}
    this.workpiece = null;
    this.capture = new Set();
    this.deleteCandidate = null;
    this.renderCount = 0;
    this.dirty = true;
    this.drag = null;             // {planeDrag, object, quaternion, last}
    this.pathVisible = { initial: true, deformed: true, simplified: true };
    this.ghostCounts = { initial: 0, deformed: 0, simplified: 0 };

    const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    renderer.setClearColor(0xdfe6ee);
    container.appendChild(renderer.domElement);
    this.renderer = renderer;

    const scene = new THREE.Scene();
    this.scene = scene;
    const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 20);
    camera.up.set(0, 0, 1);
    camera.position.set(0.2, -0.44, 0.36);
    this.camera = camera;
    const controls = new OrbitControls(camera, renderer.domElement);
    controls.target.set(0, 0, 0.02);
    controls.enableDamping = false;
    controls.addEventListener('change', () => this.requestRender());
    controls.update();
    this.controls = controls;

    scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8070, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(0.4, -0.6, 1.2);
    scene.add(sun);
    const fill = new THREE.DirectionalLight(0xffffff, 0.5);
    fill.position.set(-0.6, 0.5, 0.4);
    scene.add(fill);

    this.worldGroup = new THREE.Group();
    scene.add(this.worldGroup);
    this.ghostGroup = new THREE.Group();
    scene.add(this.ghostGroup);
    this.gripper = this.makeGripper();
    this.gripper.visible = false;
    scene.add(this.gripper);
    this.dragger = this.makeDragger();
    this.dragger.visible = false;
    scene.add(this.dragger);

    this.raycaster = new THREE.Raycaster();
    this.pointer = new THREE.Vector2();
    this.down = null;
    const el = renderer.domElement;
    el.addEventListener('pointerdown', (e) => this.pointerDown(e));
    el.addEventListener('pointermove', (e) => this.pointerMove(e));
    el.addEventListener('pointerup', (e) => this.pointerUp(e));
    el.addEventListener('pointercancel', (e) => this.pointerUp(e, true));
    el.addEventListener('lostpointercapture', (e) => { if (this.drag) this.pointerUp(e, true); });

    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
    const loop = () => {
      if (this.dirty) { this.dirty = false; this.renderer.render(this.scene, this.camera); ++this.renderCount; }
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  requestRender() { this.dirty = true; }

  resize() {
    const w = Math.max(1, this.container.clientWidth);
    const h = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  // --- the world model -------------------------------------------------------------------

  // Rebuilds or updates the objects from world_state.objects.
  setObjects(list) {
    const seen = new Set();
    let blockIndex = 0;
    for (const o of list) {
      seen.add(o.name);
      let entry = this.objects.get(o.name);
      const shapeKey = JSON.stringify(o.shape);
      if (!entry || entry.shapeKey !== shapeKey || entry.fixed !== o.fixed) {
        if (entry) this.removeObject(o.name);
        entry = this.addObject(o, o.fixed ? 0 : blockIndex);
        entry.shapeKey = shapeKey;
      }
      if (!o.fixed) ++blockIndex;
      entry.origin = o.origin;
      this.setPose(o.name, o.world_T_object);
    }
    for (const name of [...this.objects.keys()]) if (!seen.has(name)) this.removeObject(name);
    this.refreshHighlights();
  }

  addObject(o, woodIndex) {
    const group = new THREE.Group();
    group.name = o.name;
    let color;
    if (o.name === 'table') color = kTableColor;
    else if (o.fixed) color = o.name === 'frame' ? kFrameColor : kFixedColor;
    else color = kWoods[woodIndex % kWoods.length];
    const meshes = [];
    for (const g of shapeGeometries(o.shape)) {
      const material = new THREE.MeshStandardMaterial({ color, roughness: 0.85, metalness: 0.0 });
      const mesh = new THREE.Mesh(g.geometry, material);
      const holder = new THREE.Group();
      if (g.pose) poseToObject3D(holder, g.pose);
      holder.add(mesh);
      const edges = new THREE.LineSegments(new THREE.EdgesGeometry(g.geometry),
        new THREE.LineBasicMaterial({ color: o.fixed ? 0x4a3a2a : 0x5a4020, transparent: true, opacity: 0.55 }));
      holder.add(edges);
      mesh.userData.objectName = o.name;
      meshes.push(mesh);
      group.add(holder);
    }
    this.worldGroup.add(group);
    const bounds = shapeBounds(o.shape);
    const entry = { group, meshes, fixed: o.fixed, shape: o.shape, bounds, baseColor: color,
                    size: bounds.getSize(new THREE.Vector3()), center: bounds.getCenter(new THREE.Vector3()) };
    this.objects.set(o.name, entry);
    this.requestRender();
    return entry;
  }

  removeObject(name) {
    const e = this.objects.get(name);
    if (!e) return;
    this.worldGroup.remove(e.group);
    e.group.traverse((c) => { c.geometry?.dispose(); c.material?.dispose(); });
    this.objects.delete(name);
    this.requestRender();
  }

  setPose(name, pose) {
    const e = this.objects.get(name);
    if (!e || !pose) return;
    e.pose = pose;
    poseToObject3D(e.group, pose);
    e.group.updateMatrixWorld(true);
    if (name === this.workpiece) this.placeTools();
    this.requestRender();
  }

  poseOf(name) { return this.objects.get(name)?.pose ?? null; }

  setWorkpiece(name) {
    this.workpiece = name && this.objects.has(name) ? name : null;
    this.placeTools();
    this.refreshHighlights();
  }

  setCapture(names) { this.capture = new Set(names); this.refreshHighlights(); }

  setDeleteCandidate(name) { this.deleteCandidate = name; this.refreshHighlights(); }

  refreshHighlights() {
    for (const [name, e] of this.objects) {
      const capture = this.capture.has(name);
      const candidate = name === this.deleteCandidate;
      for (const m of e.meshes) {
        m.material.color.setHex(capture ? kCaptureColor : e.baseColor);
        m.material.emissive.setHex(candidate ? 0x552222 : name === this.workpiece ? 0x2a1a00 : 0x000000);
      }
    }
    this.requestRender();
  }

  // --- gripper and dragger box (Figure 7) ---------------------------------------------------

  makeGripper() {
    const g = new THREE.Group();
    const metal = new THREE.MeshStandardMaterial({ color: 0x8c939b, metalness: 0.5, roughness: 0.35 });
    const dark = new THREE.MeshStandardMaterial({ color: 0x50565c, metalness: 0.4, roughness: 0.5 });
    this.jawA = new THREE.Mesh(new THREE.BoxGeometry(1, 1, 1), metal);
    this.jawB = new THREE.Mesh(new THREE.BoxGeometry(1, 1, 1), metal);
    this.palm = new THREE.Mesh(new THREE.BoxGeometry(1, 1, 1), dark);
    this.wrist = new THREE.Mesh(new THREE.CylinderGeometry(1, 1, 1, 24), dark);
    this.wrist.rotation.x = Math.PI / 2;   // cylinder axis along z
    g.add(this.jawA, this.jawB, this.palm, this.wrist);
    for (const m of [this.jawA, this.jawB, this.palm, this.wrist]) m.userData.tool = 'gripper';
    return g;
  }

  makeDragger() {
    const g = new THREE.Group();
    const box = new THREE.Mesh(new THREE.BoxGeometry(1, 1, 1),
      new THREE.MeshBasicMaterial({ color: 0x3d7fd9, transparent: true, opacity: 0.16, depthWrite: false, side: THREE.DoubleSide }));
    box.userData.tool = 'dragger';
    const edges = new THREE.LineSegments(new THREE.EdgesGeometry(new THREE.BoxGeometry(1, 1, 1)),
      new THREE.LineBasicMaterial({ color: 0x1f5fbf }));
    const face = new THREE.Mesh(new THREE.PlaneGeometry(1, 1),
      new THREE.MeshBasicMaterial({ color: 0x3d7fd9, transparent: true, opacity: 0.35, depthWrite: false, side: THREE.DoubleSide }));
    face.visible = false;
    g.add(box, edges, face);
    this.draggerBox = box;
    this.draggerEdges = edges;
    this.draggerFace = face;
    return g;
  }

  // Gripper across the block's narrower horizontal side, jaws from above (the plan module's
  // grasp); dragger box around the block with a margin, aligned with it.
  placeTools() {
    const e = this.workpiece ? this.objects.get(this.workpiece) : null;
    if (!e || !e.pose) {
      this.gripper.visible = false;
      if (!this.drag) this.dragger.visible = false;
      this.requestRender();
      return;
    }
    const s = e.size;
    const c = e.center;
    // gripper in the block frame
    const acrossX = s.x <= s.y;
    const open = (acrossX ? s.x : s.y) / 2 + 0.004;
    const jawT = 0.008, jawD = 0.022, jawH = Math.min(0.04, s.z * 0.6 + 0.015);
    const topZ = c.z + s.z / 2;
    poseToObject3D(this.gripper, e.pose);
    const jawSize = acrossX ? [jawT, jawD, jawH] : [jawD, jawT, jawH];
    this.jawA.scale.set(...jawSize);
    this.jawB.scale.set(...jawSize);
    const jz = topZ - jawH / 2 + Math.min(0.012, s.z * 0.3);
    if (acrossX) { this.jawA.position.set(c.x - open - jawT / 2, c.y, jz); this.jawB.position.set(c.x + open + jawT / 2, c.y, jz); }
    else { this.jawA.position.set(c.x, c.y - open - jawT / 2, jz); this.jawB.position.set(c.x, c.y + open + jawT / 2, jz); }
    const palmZ = jz + jawH / 2 + 0.006;
    const span = 2 * (open + jawT);
    this.palm.scale.set(acrossX ? span : 0.03, acrossX ? 0.03 : span, 0.012);
    this.palm.position.set(c.x, c.y, palmZ);
    this.wrist.scale.set(0.014, 0.05, 0.014);
    this.wrist.position.set(c.x, c.y, palmZ + 0.006 + 0.025);
    this.gripper.visible = true;
    if (!this.drag) {
      poseToObject3D(this.dragger, e.pose);
      this.dragger.position.add(c.clone().applyQuaternion(this.dragger.quaternion));
      this.dragger.scale.set(s.x + 2 * kDraggerMargin_m, s.y + 2 * kDraggerMargin_m, s.z + 2 * kDraggerMargin_m);
      this.dragger.visible = true;
    }
    this.requestRender();
  }

  // --- the work site's gripper (robot_state.world_T_tool) -----------------------------------------

  // Tool frame (robot module): origin midway between the finger pads, z the approach direction,
  // y the closing direction. Drawn as a translucent steel-blue gripper, so the operator sees the
  // real robot follow the program during execution.
  setRobotTool(world_T_tool, width_m) {
    if (!this.robotTool) {
      const g = new THREE.Group();
      const mat = new THREE.MeshStandardMaterial({ color: 0x4a7fc1, transparent: true, opacity: 0.55, roughness: 0.4, depthWrite: false });
      const jaw = new THREE.BoxGeometry(0.02, 0.008, 0.045);
      this.robotJawA = new THREE.Mesh(jaw, mat);
      this.robotJawB = new THREE.Mesh(jaw, mat);
      const palm = new THREE.Mesh(new THREE.BoxGeometry(0.03, 1, 0.012), mat);
      this.robotPalm = palm;
      const wrist = new THREE.Mesh(new THREE.CylinderGeometry(0.018, 0.018, 0.06, 20), mat);
      wrist.rotation.x = Math.PI / 2;
      wrist.position.set(0, 0, -0.075);
      g.add(this.robotJawA, this.robotJawB, palm, wrist);
      g.traverse((c) => { c.raycast = () => {}; });
      this.robotTool = g;
      this.robotTool.visible = this.robotToolVisible ?? true;
      this.scene.add(g);
    }
    const half = Math.max(0, width_m) / 2 + 0.004;
    this.robotJawA.position.set(0, -half, -0.0125);
    this.robotJawB.position.set(0, half, -0.0125);
    this.robotPalm.scale.set(1, 2 * half + 0.008, 1);
    this.robotPalm.position.set(0, 0, -0.041);
    poseToObject3D(this.robotTool, world_T_tool);
    this.requestRender();
  }

  // --- the whole arm (issue 8 §4: a toggle shows it) ----------------------------------------------

  // The robot's table (world_state.robot.kinematics) and placement; null: no arm can be drawn.
  setRobotKinematics(kinematics, world_T_base) {
    const key = JSON.stringify([kinematics, world_T_base]);
    if (key === this.armKey) return;
    this.armKey = key;
    this.kinematics = kinematics && world_T_base ? checkKinematics(kinematics) : null;
    this.worldTBase = world_T_base ?? null;
    this.updateArm();
  }

  // The joint angles the work site streams (robot_state.joints_rad).
  setRobotJoints(joints_rad) { this.armJoints = joints_rad.slice(); if (this.armVisible) this.updateArm(); }

  setArmVisible(visible) {
    const turnedOn = visible && !this.armVisible;
    this.armVisible = visible;
    this.updateArm();
    if (turnedOn && this.arm.visible) this.frameArm();
  }

  // Pulls the view back (same direction) until the arm and the work area both fit: the robot
  // stands at the edge of the table, mostly outside the default view.
  frameArm() {
    const box = new THREE.Box3().setFromObject(this.arm);
    box.expandByObject(this.worldGroup);
    const sphere = box.getBoundingSphere(new THREE.Sphere());
    const dir = this.camera.position.clone().sub(this.controls.target).normalize();
    const halfFov = THREE.MathUtils.degToRad(this.camera.fov / 2);
    const fit = Math.min(halfFov, Math.atan(Math.tan(halfFov) * this.camera.aspect));
    const distance = sphere.radius / Math.sin(fit) * 1.02;
    this.controls.target.copy(sphere.center);
    this.camera.position.copy(sphere.center).addScaledVector(dir, distance);
    this.camera.far = Math.max(this.camera.far, distance * 4);
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.requestRender();
  }

  // Links as grey cylinders between successive DH frame origins, joints as dark spheres, the
  // flange-to-tool stretch thinner (the gripper itself is the robot tool drawn by setRobotTool).
  updateArm() {
    if (!this.arm) {
      this.arm = new THREE.Group();
      this.arm.name = 'arm';
      this.armLinkMaterial = new THREE.MeshStandardMaterial({ color: 0xe8e4da, roughness: 0.5, metalness: 0.1 });
      this.armJointMaterial = new THREE.MeshStandardMaterial({ color: 0x3b3f45, roughness: 0.4, metalness: 0.3 });
      this.armCylinder = new THREE.CylinderGeometry(1, 1, 1, 20);
      this.armSphere = new THREE.SphereGeometry(1, 20, 12);
      this.scene.add(this.arm);
    }
    const show = !!(this.armVisible && this.kinematics && this.armJoints);
    this.arm.visible = show;
    this.armTool = null;
    if (show) {
      const frames = armFrames(this.kinematics, this.worldTBase, this.armJoints);
      const segments = armSegments(frames);
      while (this.arm.children.length) this.arm.remove(this.arm.children[0]);
      const up = new THREE.Vector3(0, 1, 0);
      // a pedestal under the base frame, down to the table
      const base = frames[0].p;
      const pedestal = new THREE.Mesh(this.armCylinder, this.armJointMaterial);
      pedestal.scale.set(0.07, Math.max(0.01, base[2] + 0.025), 0.07);
      pedestal.position.set(base[0], base[1], (base[2] - 0.025) / 2);
      pedestal.quaternion.setFromUnitVectors(up, new THREE.Vector3(0, 0, 1));
      this.arm.add(pedestal);
      segments.forEach((s, i) => {
        const a = new THREE.Vector3(...s.from);
        const b = new THREE.Vector3(...s.to);
        const d = b.clone().sub(a);
        const last = i === segments.length - 1;
        const radius = last ? 0.012 : i === 0 ? 0.05 : 0.035;
        const link = new THREE.Mesh(this.armCylinder, this.armLinkMaterial);
        link.scale.set(radius, d.length(), radius);
        link.position.copy(a).add(b).multiplyScalar(0.5);
        link.quaternion.setFromUnitVectors(up, d.normalize());
        link.userData.armLink = i;
        this.arm.add(link);
        const joint = new THREE.Mesh(this.armSphere, this.armJointMaterial);
        joint.scale.setScalar(last ? 0.016 : radius * 1.1);
        joint.position.copy(a);
        this.arm.add(joint);
      });
      this.arm.traverse((c) => { c.raycast = () => {}; });   // the arm is not clickable
      this.armSegmentCount = segments.length;
      const tool = frames[frames.length - 1];
      this.armTool = { position: tool.p.slice(), quaternion_wxyz: matrixToQuat(tool.R) };
    }
    this.requestRender();
  }

  setRobotToolVisible(visible) {
    this.robotToolVisible = visible;
    if (this.robotTool) { this.robotTool.visible = visible; this.requestRender(); }
  }

  // --- paths as ghost blocks (Figure 12) ---------------------------------------------------

  setPaths(paths, workpieceName) {
    while (this.ghostGroup.children.length) {
      const c = this.ghostGroup.children.pop();
      c.geometry?.dispose(); c.material?.dispose();
    }
    this.ghostCounts = { initial: 0, deformed: 0, simplified: 0 };
    const e = workpieceName ? this.objects.get(workpieceName) : null;
    if (!paths || !e) { this.requestRender(); return; }
    const size = e.size;
    for (const kind of ['initial', 'deformed', 'simplified']) {
      const poses = paths[kind] ?? [];
      if (!poses.length) continue;
      const stride = Math.max(1, Math.ceil(poses.length / kMaxGhosts));
      const picked = poses.filter((_, i) => i % stride === 0 || i === poses.length - 1);
      const geometry = new THREE.BoxGeometry(size.x / 2, size.y / 2, size.z / 2);
      const material = new THREE.MeshStandardMaterial({ color: kPathColors[kind], roughness: 0.6,
        transparent: kind !== 'simplified', opacity: kind === 'initial' ? 0.55 : kind === 'deformed' ? 0.6 : 1 });
      const mesh = new THREE.InstancedMesh(geometry, material, picked.length);
      const o = new THREE.Object3D();
      picked.forEach((pose, i) => {
        poseToObject3D(o, pose);
        o.position.add(e.center.clone().applyQuaternion(o.quaternion));
        o.updateMatrix();
        mesh.setMatrixAt(i, o.matrix);
      });
      mesh.userData.path = kind;
      mesh.visible = this.pathVisible[kind];
      mesh.raycast = () => {};   // ghosts are not clickable
      this.ghostGroup.add(mesh);
      this.ghostCounts[kind] = picked.length;
      if (kind === 'simplified' && picked.length > 1) {
        const pts = picked.map((p) => new THREE.Vector3(...p.position).add(e.center.clone().applyQuaternion(
          new THREE.Quaternion(p.quaternion_wxyz[1], p.quaternion_wxyz[2], p.quaternion_wxyz[3], p.quaternion_wxyz[0]))));
        const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints(pts), new THREE.LineBasicMaterial({ color: 0x1b7a43 }));
        line.userData.path = kind;
        line.visible = this.pathVisible[kind];
        line.raycast = () => {};
        this.ghostGroup.add(line);
      }
    }
    // the workpiece's start as a grey shadow block (Figure 12a)
    const first = (paths.initial ?? [])[0];
    if (first) {
      const shadow = new THREE.Mesh(new THREE.BoxGeometry(size.x, size.y, size.z),
        new THREE.MeshStandardMaterial({ color: 0x888888, transparent: true, opacity: 0.35, depthWrite: false }));
      poseToObject3D(shadow, first);
      shadow.position.add(e.center.clone().applyQuaternion(shadow.quaternion));
      shadow.raycast = () => {};
      this.ghostGroup.add(shadow);
    }
    this.requestRender();
  }

  setPathVisible(kind, visible) {
    this.pathVisible[kind] = visible;
    for (const c of this.ghostGroup.children) if (c.userData.path === kind) c.visible = visible;
    this.requestRender();
  }

  // --- picking and dragging ----------------------------------------------------------------

  rayFromEvent(e) {
    const r = this.renderer.domElement.getBoundingClientRect();
    this.pointer.set(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1);
    this.raycaster.setFromCamera(this.pointer, this.camera);
    return this.raycaster.ray;
  }

  pickDraggerFace(e) {
    if (!this.dragger.visible) return null;
    this.rayFromEvent(e);
    const hits = this.raycaster.intersectObject(this.draggerBox, false);
    if (!hits.length) return null;
    const h = hits[0];
    const normal = h.face.normal.clone().transformDirection(this.draggerBox.matrixWorld).normalize();
    return { point: h.point.clone(), normal, localNormal: h.face.normal.clone() };
  }

  pickObject(e) {
    this.rayFromEvent(e);
    const meshes = [];
    for (const entry of this.objects.values()) meshes.push(...entry.meshes);
    const hits = this.raycaster.intersectObjects(meshes, false);
    return hits.length ? hits[0].object.userData.objectName : null;
  }

  pointerDown(e) {
    if (e.button !== 0) return;
    this.down = { x: e.clientX, y: e.clientY, shift: e.shiftKey };
    const face = e.shiftKey ? null : this.pickDraggerFace(e);
    if (face && this.workpiece && this.onDrag) {
      const entry = this.objects.get(this.workpiece);
      const start = entry.pose.position;
      // the stroke begins with the first motion: a click on the box records nothing
      this.drag = {
        object: this.workpiece,
        plane: new PlaneDrag([face.point.x, face.point.y, face.point.z], [face.normal.x, face.normal.y, face.normal.z], start),
        quaternion: entry.pose.quaternion_wxyz.slice(),
        boxStart: this.dragger.position.clone(),
        last: start.slice(),
        started: false,
      };
      this.controls.enabled = false;
      this.renderer.domElement.setPointerCapture(e.pointerId);
      this.showFace(face);
      e.preventDefault();
    }
  }

  pointerMove(e) {
    if (this.drag) {
      const ray = this.rayFromEvent(e);
      const p = this.drag.plane.update([ray.origin.x, ray.origin.y, ray.origin.z], [ray.direction.x, ray.direction.y, ray.direction.z]);
      if (p && Math.hypot(p[0] - this.drag.last[0], p[1] - this.drag.last[1], p[2] - this.drag.last[2]) > 1e-7) {
        if (!this.drag.started) {
          this.drag.started = true;
          this.onDrag('begin', { position: this.drag.plane.start.slice(), quaternion_wxyz: this.drag.quaternion.slice() }, this.drag.object);
        }
        this.drag.last = p;
        const d = new THREE.Vector3(p[0] - this.drag.plane.start[0], p[1] - this.drag.plane.start[1], p[2] - this.drag.plane.start[2]);
        this.dragger.position.copy(this.drag.boxStart).add(d);
        this.requestRender();
        this.onDrag('move', { position: p, quaternion_wxyz: this.drag.quaternion.slice() }, this.drag.object);
      }
      return;
    }
    if (e.buttons) return;
    const face = this.pickDraggerFace(e);
    if (face) { this.showFace(face); this.renderer.domElement.style.cursor = 'move'; return; }
    if (this.draggerFace.visible) { this.draggerFace.visible = false; this.requestRender(); }
    const name = this.pickObject(e);
    this.renderer.domElement.style.cursor = name && !this.objects.get(name).fixed ? 'pointer' : 'default';
    this.onHover(name);
  }

  pointerUp(e, cancelled = false) {
    if (this.drag) {
      const d = this.drag;
      this.drag = null;
      this.controls.enabled = true;
      this.draggerFace.visible = false;
      if (d.started) {
        this.onDrag('end', { position: d.last, quaternion_wxyz: d.quaternion.slice() }, d.object);
        this.placeTools();
        this.down = null;
        return;
      }
      this.placeTools();
    }
    if (cancelled || !this.down) { this.down = null; return; }
    const moved = Math.hypot(e.clientX - this.down.x, e.clientY - this.down.y);
    const shift = this.down.shift;
    this.down = null;
    if (moved > 4) return;   // that was an orbit
    const name = this.pickObject(e);
    if (shift) { if (name) this.onCapture(name); return; }
    this.onSelect(name, name ? this.objects.get(name).fixed : false);
  }

  showFace(face) {
    // put the highlight plane on the face the pointer is over (in the dragger's unit box)
    const n = face.localNormal;
    const f = this.draggerFace;
    f.position.set(n.x * 0.501, n.y * 0.501, n.z * 0.501);
    f.quaternion.copy(new THREE.Quaternion().setFromUnitVectors(new THREE.Vector3(0, 0, 1), n));
    f.visible = true;
    this.requestRender();
  }

  // --- helpers for tests and the page --------------------------------------------------------

  // Client (CSS pixel) coordinates of a world point, or null when behind the camera.
  projectToClient(p) {
    const v = new THREE.Vector3(p[0], p[1], p[2]).project(this.camera);
    if (v.z > 1) return null;
    const r = this.renderer.domElement.getBoundingClientRect();
    return { x: r.left + (v.x + 1) / 2 * r.width, y: r.top + (1 - v.y) / 2 * r.height };
  }

  // The centre of a dragger box face (+x, -x, +y, -y, +z, -z in the box frame) in world.
  draggerFaceCenter(face) {
    const axis = { '+x': [1, 0, 0], '-x': [-1, 0, 0], '+y': [0, 1, 0], '-y': [0, -1, 0], '+z': [0, 0, 1], '-z': [0, 0, -1] }[face];
    if (!axis || !this.dragger.visible) return null;
    this.dragger.updateMatrixWorld(true);
    const p = new THREE.Vector3(axis[0] * 0.5, axis[1] * 0.5, axis[2] * 0.5);
    this.dragger.localToWorld(p);
    return [p.x, p.y, p.z];
  }

  snapshot() {
    return {
      renderCount: this.renderCount,
      objectsDrawn: this.objects.size,
      gripperVisible: this.gripper.visible,
      draggerVisible: this.dragger.visible,
      dragging: this.drag !== null,
      draggerPosition: this.dragger.visible ? this.dragger.position.toArray() : null,
      ghosts: { ...this.ghostCounts },
      robotToolVisible: !!(this.robotTool && this.robotTool.visible),
      arm: { available: !!this.kinematics, visible: !!(this.arm && this.arm.visible),
             links: this.arm && this.arm.visible ? this.armSegmentCount : 0,
             tool: this.armTool ? structuredClone(this.armTool) : null },
    };
  }
}
