// The operator's page: wires the link to the four windows of the paper's Figure 5 (camera image,
// feedback, model view, console), the task panel and the status line. The operator site owns all
// state; the page shows the latest world_state and turns clicks into protocol messages.
import { Link, LinkProxy } from './link.js';
import { ModelView } from './model_view.js';
import { CameraView, scoreColor } from './camera_view.js';
import { formatMm, yawOf } from './protocol.js';

const $ = (id) => document.getElementById(id);
const kMaxConsoleLines = 500;
const kMoveInterval_ms = 15;   // dragger moves at most ~66 Hz: the simulator steps at >= 60 Hz

const params = new URLSearchParams(location.search);
const wsUrl = params.get('ws') ?? `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`;

const ui = {
  world: null,              // the latest world_state
  worksiteLink: null,       // the latest link_state (work-site link)
  recognitions: null,
  robot: null,              // the latest robot_state
  progress: null,           // the latest execution_progress
  reportMsg: null,          // the latest report message
  poseUpdates: 0,
  progressEvents: 0,        // execution_progress / report messages that were news (not replays)
  reportEvents: 0,
  lastPoseUpdate: null,
  simRate_hz: null,
  consoleLines: [],         // {kind: 'cmd'|'out'|'fail'|'note', text}
  errors: [],               // {source, code, message, t}
  selected: null,           // last clicked object (for Delete)
  linkEvents: [],           // {state, reason, t}
};

// the link in a worker (see link.js); on the main thread only where workers are missing or
// disabled with ?worker=0
const link = typeof Worker !== 'undefined' && params.get('worker') !== '0'
  ? new LinkProxy(wsUrl, { clientName: 'browser' }) : new Link(wsUrl, { clientName: 'browser' });
const modelView = new ModelView($('model-view'), {
  onSelect: (name, fixed) => selectClicked(name, fixed),
  onCapture: (name) => command(`capture ${name}`),
  onDrag: (phase, pose, object) => dragInput(phase, pose, object),
});
const cameraView = new CameraView($('camera-canvas'), $('camera-info'));

// --- errors -----------------------------------------------------------------------------------

function showError(source, message, code = '') {
  const entry = { source, code, message, t: new Date().toISOString() };
  ui.errors.push(entry);
  if (ui.errors.length > 50) ui.errors.shift();
  const box = $('errors');
  const div = document.createElement('div');
  div.className = 'error';
  const text = document.createElement('span');
  text.textContent = `${source}: ${message}${code ? ` (${code})` : ''}`;
  const close = document.createElement('button');
  close.textContent = '×';
  close.title = 'dismiss';
  close.onclick = () => div.remove();
  div.append(text, close);
  box.append(div);
  while (box.children.length > 4) box.firstChild.remove();
  setTimeout(() => div.remove(), 15000);
  addConsole('fail', `${source}: ${message}`);
}

link.on('local_error', (text) => showError('page', text));
link.on('error', (m) => showError('operator', m.message, m.code));
link.on('seq_gap', ({ seq, type }) => addConsole('note', `gap in the operator's messages before ${type} #${seq} (dropped by the sender)`));

// --- link and status line -------------------------------------------------------------------

link.on('link', ({ state, reason }) => {
  ui.linkEvents.push({ state, reason, t: performance.now() / 1000 });
  if (state === 'down') addConsole('fail', `link to the operator site lost: ${reason}; reconnecting…`);
  if (state === 'silent') addConsole('fail', `operator site silent: ${reason}`);
  if (state === 'up' && reason.startsWith('session')) {
    const wasLost = ui.linkEvents.some((e) => e.state === 'down');
    addConsole('note', wasLost ? `link to the operator site restored (${reason})` : `connected to the operator site (${reason})`);
  }
  updateStatus();
});

function setItem(id, cls, text) {
  const el = $(id);
  el.classList.remove('ok', 'warn', 'bad');
  if (cls) el.classList.add(cls);
  el.querySelector('.value').textContent = text;
}

function worksiteLink() {
  // the newer of the relayed link_state and world_state.link: both carry the same event
  return ui.worksiteLink ?? ui.world?.link ?? null;
}

function updateStatus() {
  const reconnecting = link.reconnects > 0 ? ` (attempt ${link.reconnects})` : '';
  if (link.state === 'up') setItem('st-link', 'ok', `connected, session ${link.session}`);
  else if (link.state === 'silent') setItem('st-link', 'warn', link.stateReason);
  else if (link.state === 'connecting') setItem('st-link', 'warn', `connecting${reconnecting}…`);
  else setItem('st-link', 'bad', `LOST — reconnecting${reconnecting}`);

  const ws = worksiteLink();
  const resume = $('btn-resume');
  if (!ws || link.state !== 'up') { setItem('st-worksite', '', '—'); resume.hidden = true; }
  else {
    const stopped = ws.stopped ? ' — robot STOPPED' : '';
    if (ws.state === 'up') setItem('st-worksite', ws.stopped ? 'warn' : 'ok', `connected${stopped}`);
    else setItem('st-worksite', 'bad', `LOST: ${ws.reason}${ws.silent_s != null ? ` (silent ${ws.silent_s.toFixed(2)} s)` : ''}${stopped}`);
    resume.hidden = !(ws.stopped && link.holdsLease());
  }

  const rtt = link.rtt_s != null ? `${(link.rtt_s * 1000).toFixed(1)} ms` : '—';
  const wsRtt = ui.world?.link?.rtt_s;
  setItem('st-latency', '', wsRtt != null ? `${rtt} · work site ${(wsRtt * 1000).toFixed(1)} ms` : rtt);

  const rate = ui.simRate_hz ?? ui.world?.sim_rate_hz;
  setItem('st-sim', rate ? (rate >= 60 ? 'ok' : 'warn') : '', rate ? `${rate.toFixed(0)} steps/s` : 'idle');

  const btnLease = $('btn-lease');
  if (link.state !== 'up') { setItem('st-lease', '', '—'); btnLease.hidden = true; }
  else if (link.holdsLease()) { setItem('st-lease', 'ok', 'you'); btnLease.hidden = true; }
  else if (link.leaseHolder === null) { setItem('st-lease', 'warn', 'nobody — you are watching'); btnLease.hidden = false; }
  else { setItem('st-lease', 'warn', `session ${link.leaseHolder} — you are watching`); btnLease.hidden = true; }

  const busy = ui.world?.busy;
  $('st-busy').querySelector('.value').textContent = busy === 'planning' ? 'generating the program…' : busy === 'executing' ? 'robot executing…' : '';
  updateButtons();
}

setInterval(updateStatus, 250);
$('btn-lease').onclick = () => link.requestLease();
$('btn-resume').onclick = () => { link.send('resume'); addConsole('cmd', '(resume robot)'); };

// --- world state ------------------------------------------------------------------------------

link.on('welcome', () => {
  ui.simRate_hz = null;
  updateStatus();
});

link.on('world_state', (m) => {
  if (ui.world && m.revision < ui.world.revision && link.session === ui.worldSession) return;
  ui.world = m;
  ui.worldSession = link.session;
  ui.worksiteLink = null;   // world_state.link is the newest now
  try {
    modelView.setObjects(m.objects);
  } catch (e) {
    showError('page', `cannot draw the model: ${e.message}`);
  }
  modelView.setWorkpiece(m.workpiece);
  modelView.setCapture(m.capture ?? []);
  if (ui.selected && !m.objects.some((o) => o.name === ui.selected)) ui.selected = null;
  modelView.setDeleteCandidate(ui.selected);
  try {
    modelView.setRobotKinematics(m.robot?.kinematics ?? null, m.robot?.base ?? null);
  } catch (e) {
    showError('page', `cannot draw the arm: ${e.message}`);
  }
  $('arm-toggle').hidden = !m.robot?.kinematics;
  cameraView.setCameras(m.cameras);
  cameraView.setModels(m.models);
  const pathsKey = JSON.stringify([m.workpiece, m.paths]);
  if (pathsKey !== ui.pathsKey) {
    ui.pathsKey = pathsKey;
    modelView.setPaths(m.paths, m.workpiece);
  }
  const anyPath = m.paths && ['initial', 'deformed', 'simplified'].some((k) => (m.paths[k] ?? []).length);
  $('legend').hidden = !anyPath;
  if (!m.dragging) ui.simRate_hz = null;
  followStroke(m);
  renderTask();
  renderFeedback();
  updateStatus();
});

link.on('pose_update', (m) => {
  ++ui.poseUpdates;
  ui.lastPoseUpdate = m;
  for (const p of m.poses) modelView.setPose(p.object, p.world_T_object);
  if (m.sim_rate_hz != null) ui.simRate_hz = m.sim_rate_hz;
  if (ui.world && ui.world.workpiece && m.poses.some((p) => p.object === ui.world.workpiece)) renderTask();
});

link.on('link_state', (m) => {
  const before = worksiteLink();
  ui.worksiteLink = m;
  if (!before || before.state !== m.state || before.stopped !== m.stopped) {
    const text = m.state === 'up' ? `work site connected${m.stopped ? ', robot stopped (press Resume robot)' : ''}`
                                  : `work site link LOST: ${m.reason}${m.stopped ? ', robot stopped' : ''}`;
    addConsole(m.state === 'up' && !m.stopped ? 'note' : 'fail', text);
  }
  updateStatus();
});

link.on('lease_grant', (m) => {
  if (!m.granted) addConsole('note', `control not granted${m.reason ? `: ${m.reason}` : ''}; you are watching`);
  updateStatus();
});
link.on('lease_state', () => updateStatus());

link.on('camera_frame', (f) => cameraView.setFrame(f));
link.on('recognitions', (m) => { ui.recognitions = m; cameraView.setRecognitions(m); renderFeedback(); });
link.on('robot_state', (m) => {
  ui.robot = m;
  $('robot-toggle').hidden = false;
  modelView.setRobotTool(m.world_T_tool, m.gripper_width_m);
  modelView.setRobotJoints(m.joints_rad);
});
$('show-robot').onchange = (e) => modelView.setRobotToolVisible(e.target.checked);
$('show-arm').onchange = (e) => modelView.setArmVisible(e.target.checked);
// A replayed progress or report (sent on (re)connecting, docs/protocol.md) is the state as it
// is: shown, but not counted as an event.
link.on('execution_progress', (m) => { ui.progress = m; if (!m.replay) ++ui.progressEvents; renderProgress(); });
link.on('report', (m) => { ui.reportMsg = m; if (!m.replay) ++ui.reportEvents; renderTask(); });

// --- task panel ---------------------------------------------------------------------------------

function renderTask() {
  const w = ui.world;
  if (!w) return;
  const wp = w.workpiece;
  if (wp) {
    const pose = modelView.poseOf(wp);
    const where = pose ? ` at ${formatMm(pose.position)}, turned ${(yawOf(pose.quaternion_wxyz) * 180 / Math.PI).toFixed(1)}°` : '';
    $('task-workpiece').textContent = `${wp}${where}`;
  } else {
    $('task-workpiece').textContent = 'none — click a block in the model';
  }
  $('task-capture').textContent = w.capture?.length ? w.capture.join(', ') : 'nothing (shift-click an object)';
  $('task-strokes').textContent = `${w.demonstrations}${w.dragging ? ' (dragging)' : ''}`;
  $('task-selected').textContent = ui.selected ?? '—';
  $('model-info').textContent = `${w.objects.length} objects, revision ${w.revision}`;

  if (w.program) {
    $('program-info').textContent = `${w.program.id}, ${w.program.command_count} commands`;
    $('program-listing').textContent = w.program.listing;
  } else {
    $('program-info').textContent = w.busy === 'planning' ? 'generating…' : '';
    $('program-listing').textContent = w.busy === 'planning' ? 'Generating the program…' : 'No program yet: move the block, then press Confirm.';
  }
  const result = $('result');
  const rep = w.report;
  result.classList.remove('ok', 'bad');
  if (rep) {
    result.classList.add(rep.ok ? 'ok' : 'bad');
    result.textContent = `${rep.ok ? '✓ Verified' : '✗ Not verified'} (${rep.program_id}): ${rep.summary}`;
  } else {
    result.textContent = w.busy === 'executing' ? 'executing…' : '—';
  }
  renderProgress();
  updateButtons();
}

function renderProgress() {
  const p = ui.progress;
  const el = $('progress');
  el.classList.remove('done', 'failed', 'stopped');
  const bar = el.querySelector('.bar');
  const text = el.querySelector('.text');
  if (!p || (ui.world?.program && p.program_id !== ui.world.program.id && ui.world.busy !== 'executing')) {
    bar.style.width = '0';
    text.textContent = 'not started';
    return;
  }
  const frac = p.command_count ? p.command_index / p.command_count : 0;
  bar.style.width = `${(frac * 100).toFixed(0)}%`;
  if (p.state !== 'running') el.classList.add(p.state);
  text.textContent = `${p.program_id}: ${p.state}, command ${p.command_index} of ${p.command_count}${p.message ? ` — ${p.message}` : ''}`;
}

function updateButtons() {
  const w = ui.world;
  const lease = link.holdsLease() && link.state === 'up';
  const idle = w && !w.busy;
  $('btn-confirm').disabled = !(lease && idle && w.workpiece && w.demonstrations > 0 && !w.dragging);
  const site = worksiteLink();
  $('btn-execute').disabled = !(lease && idle && w.program && site?.state === 'up' && !site.stopped);
  $('btn-execute').title = site?.stopped ? 'the robot is stopped: press "Resume robot" in the status line first' : 'run the program on the robot';
  $('btn-undo').disabled = !(lease && idle && w.demonstrations > 0 && !w.dragging);
  $('btn-deselect').disabled = !(lease && idle && w.workpiece && !w.dragging);
  $('btn-delete').disabled = !(lease && idle && ui.selected && !(w.dragging && ui.selected === w.workpiece));
  $('btn-reset').disabled = !(lease && idle);
}

$('btn-confirm').onclick = () => command('confirm');
$('btn-execute').onclick = () => { ui.progress = null; command('execute'); };
$('btn-undo').onclick = () => command('undo');
$('btn-deselect').onclick = () => command('select');
$('btn-delete').onclick = () => { if (ui.selected) command(`delete ${ui.selected}`); };
$('btn-reset').onclick = () => command('reset');
for (const box of document.querySelectorAll('#legend input[data-path]')) {
  box.onchange = () => modelView.setPathVisible(box.dataset.path, box.checked);
}

// --- model view interaction -------------------------------------------------------------------

function selectClicked(name, fixed) {
  ui.selected = name;
  modelView.setDeleteCandidate(name);
  renderTask();
  if (!name) return;
  if (!fixed && ui.world && name !== ui.world.workpiece) command(`select ${name}`);
}

let pendingMove = null;
let moveTimer = null;
let lastMoveSent_ms = 0;

function flushMove() {
  moveTimer = null;
  if (!pendingMove) return;
  link.send('dragger_input', pendingMove);
  pendingMove = null;
  lastMoveSent_ms = performance.now();
}

// A stroke the operator ended on its own (it ends a page's drag when the page's heartbeats stop
// for its browser-link timeout) while the mouse is still down continues as a new stroke at the next motion.
let stroke = { active: false, seenActive: false, needsBegin: false, restarts: 0 };

function dragInput(phase, pose, object) {
  if (!link.holdsLease()) {
    if (phase === 'begin') showError('page', 'you are watching: press "Take control" in the status line to move blocks');
    return;
  }
  const msg = { object, phase, world_T_dragger: pose };
  if (phase === 'begin') stroke = { active: true, seenActive: false, needsBegin: false, restarts: 0 };
  if (phase === 'move') {
    if (stroke.needsBegin) {
      stroke.needsBegin = false;
      ++stroke.restarts;
      clearTimeout(moveTimer);
      pendingMove = null;
      link.send('dragger_input', { object, phase: 'begin', world_T_dragger: pose });
      return;
    }
    pendingMove = msg;
    const wait = kMoveInterval_ms - (performance.now() - lastMoveSent_ms);
    if (wait <= 0) flushMove();
    else if (!moveTimer) moveTimer = setTimeout(flushMove, wait);
    return;
  }
  if (phase === 'end') {
    clearTimeout(moveTimer);
    flushMove();
    stroke.active = false;
    if (stroke.needsBegin) return;   // the operator has ended it already
  }
  link.send('dragger_input', msg);
}

function followStroke(world) {
  if (!stroke.active) return;
  if (world.dragging) { stroke.seenActive = true; return; }
  if (stroke.seenActive && !stroke.needsBegin) {
    stroke.seenActive = false;
    stroke.needsBegin = true;
    addConsole('note', 'the operator site ended the drag (this page was silent too long); moving on continues it as a new move');
  }
}

// --- feedback window --------------------------------------------------------------------------

function renderFeedback() {
  const list = $('feedback-list');
  list.textContent = '';
  const r = ui.recognitions;
  $('feedback-info').textContent = r ? `${r.objects.length} on image #${r.frame_seq}` : '';
  if (!r || !r.objects.length) {
    const li = document.createElement('li');
    li.className = 'empty';
    li.textContent = r ? 'nothing recognized in the latest image' : 'waiting for the vision system…';
    list.append(li);
    return;
  }
  r.objects.forEach((o, i) => {
    const li = document.createElement('li');
    li.dataset.index = String(i);
    li.title = `add ${o.model} to the model`;
    const idx = document.createElement('span'); idx.className = 'idx'; idx.textContent = `#${i}`;
    const mid = document.createElement('span');
    mid.innerHTML = '';
    const name = document.createElement('div'); name.textContent = o.model;
    const where = document.createElement('div'); where.className = 'where'; where.textContent = formatMm(o.world_T_object.position);
    mid.append(name, where);
    const right = document.createElement('span');
    const score = document.createElement('div'); score.className = 'score';
    const fill = document.createElement('div'); fill.style.width = `${(o.score * 100).toFixed(0)}%`; fill.style.background = scoreColor(o.score);
    score.append(fill);
    const st = document.createElement('div'); st.className = 'score-text'; st.textContent = `score ${o.score.toFixed(2)}`;
    right.append(score, st);
    li.append(idx, mid, right);
    li.onmouseenter = () => cameraView.setHover(i);
    li.onmouseleave = () => cameraView.setHover(-1);
    li.onclick = () => command(`add ${i}`);
    list.append(li);
  });
}

// --- console ---------------------------------------------------------------------------------

function addConsole(kind, text) {
  ui.consoleLines.push({ kind, text });
  if (ui.consoleLines.length > kMaxConsoleLines) ui.consoleLines.shift();
  const out = $('console-out');
  const div = document.createElement('div');
  div.className = kind;
  div.textContent = kind === 'cmd' ? `> ${text}` : text;
  out.append(div);
  while (out.children.length > kMaxConsoleLines) out.firstChild.remove();
  out.scrollTop = out.scrollHeight;
}

function command(line) {
  if (!link.send('console_command', { line })) { showError('page', `not connected: "${line}" was not sent`); return; }
  addConsole('cmd', line);
}

link.on('console_output', (m) => {
  addConsole(m.ok ? 'out' : 'fail', m.text);
  if (!m.ok && m.in_reply_to != null) showError('command', m.text.split('\n')[0]);
});

const history = [];
let historyAt = 0;
$('console-form').addEventListener('submit', (e) => {
  e.preventDefault();
  const input = $('console-input');
  const line = input.value.trim();
  if (!line) return;
  if (history[history.length - 1] !== line) history.push(line);
  historyAt = history.length;
  input.value = '';
  if (line === 'clear') { $('console-out').textContent = ''; return; }
  command(line);
});
$('console-input').addEventListener('keydown', (e) => {
  const input = e.target;
  if (e.key === 'ArrowUp' && historyAt > 0) { input.value = history[--historyAt]; e.preventDefault(); }
  else if (e.key === 'ArrowDown') {
    if (historyAt < history.length - 1) input.value = history[++historyAt];
    else { historyAt = history.length; input.value = ''; }
    e.preventDefault();
  }
});

// --- read-only view for tests and the curious ------------------------------------------------

function deepFreeze(o) {
  if (o && typeof o === 'object') { Object.freeze(o); for (const v of Object.values(o)) deepFreeze(v); }
  return o;
}

function snapshot() {
  const w = ui.world;
  const objects = {};
  for (const [name, e] of modelView.objects) {
    objects[name] = { fixed: e.fixed, origin: e.origin, pose: e.pose ? structuredClone(e.pose) : null };
  }
  return {
    link: { state: link.state, reason: link.stateReason, session: link.session, rtt_s: link.rtt_s,
            reconnects: link.reconnects, errorsReceived: link.errorsReceived },
    lease: { holder: link.leaseHolder, mine: link.holdsLease() },
    worksite: worksiteLink() ? structuredClone(worksiteLink()) : null,
    revision: w?.revision ?? 0,
    objects,
    workpiece: w?.workpiece ?? null,
    capture: w?.capture ?? [],
    dragging: w?.dragging ?? false,
    demonstrations: w?.demonstrations ?? 0,
    busy: w?.busy ?? '',
    paths: w ? { initial: w.paths.initial.length, deformed: w.paths.deformed.length, simplified: w.paths.simplified.length } : null,
    program: w?.program ? structuredClone(w.program) : null,
    report: w?.report ? structuredClone(w.report) : null,
    progress: ui.progress ? structuredClone(ui.progress) : null,
    progressEvents: ui.progressEvents,
    resync: link.resync ? structuredClone(link.resync) : null,
    reportEvents: ui.reportEvents,
    recognitionList: ui.recognitions ? ui.recognitions.objects.map((o) => ({ model: o.model, score: o.score,
                                                                         position: o.world_T_object.position.slice() })) : [],
    poseUpdates: ui.poseUpdates,
    simRate_hz: ui.simRate_hz ?? w?.sim_rate_hz ?? null,
    camera: cameraView.snapshot(),
    recognitions: ui.recognitions ? ui.recognitions.objects.length : 0,
    feedbackItems: document.querySelectorAll('#feedback-list li[data-index]').length,
    console: ui.consoleLines.slice(-100),
    errors: ui.errors.slice(),
    view: modelView.snapshot(),
    strokeRestarts: stroke.restarts,
    robot: ui.robot ? { moving: ui.robot.moving, stopped: ui.robot.stopped, gripper_width_m: ui.robot.gripper_width_m,
                        world_T_tool: structuredClone(ui.robot.world_T_tool) } : null,
    status: Object.fromEntries([...document.querySelectorAll('#statusbar .status-item')].map((el) =>
      [el.id.replace('st-', ''), el.querySelector('.value').textContent])),
  };
}

Object.defineProperty(window, 'teachsimState', { get: () => deepFreeze(snapshot()), enumerable: true });
Object.defineProperty(window, 'teachsimView', {
  value: Object.freeze({
    projectToClient: (p) => modelView.projectToClient(p),
    draggerFaceCenter: (face) => modelView.draggerFaceCenter(face),
  }),
});

window.addEventListener('beforeunload', () => link.close());
link.connect();
updateStatus();
