// The browser's end of the operator link (docs/protocol.md): hello, sequence numbers both ways,
// heartbeats with round-trip time, a watchdog for silence, the controller lease, and reconnection
// with back-off. Knows nothing about what the messages mean; the UI subscribes by type.
//
// The link runs in a dedicated worker (link_worker.js) when the browser has one: the operator
// ends a drag when a page's heartbeats stop for its browser-link timeout, and a page's main thread
// can stall (software WebGL on a busy machine, a background tab); the worker's timers are not held up by it.
// `LinkProxy` is the main thread's view of it, with the same interface as `Link`.
import { kProtocolVersion, Sequencer, SeqTracker, parseBinaryFrame } from './protocol.js';

const kDefaultHeartbeat_s = 0.05;
const kDefaultTimeout_s = 2.0;   // until welcome.link_timeout_s says otherwise

export class Link {
  constructor(url, { clientName = 'teachsim-web', clock = () => performance.now() / 1000 } = {}) {
    this.url = url;
    this.clientName = clientName;
    this.now = clock;
    this.listeners = new Map();
    this.ws = null;
    this.state = 'connecting';   // connecting | up | silent | down
    this.session = null;
    this.leaseHolder = null;
    this.rtt_s = null;
    this.peerSilent_s = 0;
    this.reconnects = 0;
    this.errorsReceived = 0;
    this.lastError = null;
    this.heartbeat_s = kDefaultHeartbeat_s;
    this.timeout_s = kDefaultTimeout_s;
    this.backoff_s = 0.25;
    this.wantLease = true;
    this.timer = null;
    this.reconnectTimer = null;
    this.closedByUs = false;
  }

  on(type, fn) {
    if (!this.listeners.has(type)) this.listeners.set(type, []);
    this.listeners.get(type).push(fn);
  }

  emit(type, msg) {
    if (this.sink && type !== '*') this.sink(type, msg);
    for (const fn of this.listeners.get(type) ?? []) {
      try { fn(msg); } catch (e) { console.error(`handler for ${type} failed`, e); this.emitLocalError(`UI handler for ${type}: ${e.message}`); }
    }
  }

  emitLocalError(text) {
    if (this.sink) this.sink('local_error', text);
    for (const fn of this.listeners.get('local_error') ?? []) fn(text);
  }

  status() {
    return { state: this.state, stateReason: this.stateReason ?? '', session: this.session, leaseHolder: this.leaseHolder,
             resync: this.resync ? { world_ms: this.resync.world_ms, progress_ms: this.resync.progress_ms } : null,
             rtt_s: this.rtt_s, reconnects: this.reconnects, errorsReceived: this.errorsReceived, open: !!(this.ws && this.ws.readyState === 1) };
  }

  holdsLease() { return this.session !== null && this.leaseHolder === this.session; }

  connect() {
    this.closedByUs = false;
    this.out = new Sequencer();
    this.in = new SeqTracker();
    this.lastRx_s = this.now();
    this.peerHeartbeat = null;   // {t_s, received_s}
    this.session = null;
    this.setState('connecting');
    let ws;
    try {
      ws = new WebSocket(this.url);
    } catch (e) {
      this.emitLocalError(`cannot open ${this.url}: ${e.message}`);
      this.scheduleReconnect();
      return;
    }
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    ws.onopen = () => {
      if (ws !== this.ws) return;
      this.lastRx_s = this.now();
      this.helloSeq = this.send('hello', { client: this.clientName, protocol: kProtocolVersion });
      this.startTimer();
    };
    ws.onmessage = (ev) => { if (ws === this.ws) this.receive(ev.data); };
    ws.onclose = (ev) => {
      if (ws !== this.ws) return;
      this.stopTimer();
      this.ws = null;
      this.session = null;
      this.setState('down', ev.code === 1000 || !ev.reason ? `closed (${ev.code})` : `closed: ${ev.reason} (${ev.code})`);
      if (!this.closedByUs) this.scheduleReconnect();
    };
    ws.onerror = () => { /* onclose follows and reports */ };
  }

  close() {
    this.closedByUs = true;
    clearTimeout(this.reconnectTimer);
    this.stopTimer();
    if (this.ws) this.ws.close(1000, 'page closed');
  }

  scheduleReconnect() {
    clearTimeout(this.reconnectTimer);
    const delay = this.backoff_s;
    this.backoff_s = Math.min(2, this.backoff_s * 2);
    this.reconnectTimer = setTimeout(() => { ++this.reconnects; this.connect(); }, delay * 1000);
  }

  setState(state, reason = '') {
    const changed = state !== this.state;
    this.state = state;
    this.stateReason = reason;
    if (changed) this.emit('link', { state, reason });
  }

  startTimer() {
    this.stopTimer();
    this.timer = setInterval(() => this.tick(), this.heartbeat_s * 1000);
  }

  stopTimer() { if (this.timer) clearInterval(this.timer); this.timer = null; }

  tick() {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return;
    const now = this.now();
    const hb = { t_s: now };
    if (this.peerHeartbeat) {
      hb.echo_t_s = this.peerHeartbeat.t_s;
      hb.hold_s = Math.max(0, now - this.peerHeartbeat.received_s);
    }
    this.send('heartbeat', hb);
    this.peerSilent_s = now - this.lastRx_s;
    // The operator's browser-link timeout (welcome.link_timeout_s, 2 s by default: browsers
    // throttle background tabs) is the page's too; at least 1 s, for a stalled main thread.
    if (this.state === 'up' && this.peerSilent_s > Math.max(1, this.timeout_s)) {
      this.setState('silent', `operator silent for ${this.peerSilent_s.toFixed(2)} s`);
    }
  }

  // Sends a message; returns its seq, or null when the link is not open.
  send(type, fields = {}) {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return null;
    const seq = this.out.take();
    this.ws.send(JSON.stringify({ type, seq, ...fields }));
    return seq;
  }

  receive(data) {
    this.lastRx_s = this.now();
    if (this.state === 'silent') this.setState('up', 'operator heard again');
    if (data instanceof ArrayBuffer) {
      let frame;
      try { frame = parseBinaryFrame(data); } catch (e) { this.emitLocalError(e.message); return; }
      this.checkSeq(frame.seq, 'camera_frame');
      this.emit('camera_frame', frame);
      return;
    }
    let msg;
    try { msg = JSON.parse(data); } catch (e) { this.emitLocalError(`operator sent text that is not JSON: ${e.message}`); return; }
    if (!msg || typeof msg !== 'object' || typeof msg.type !== 'string') {
      this.emitLocalError('operator sent a message without a type');
      return;
    }
    this.checkSeq(msg.seq, msg.type);
    // How long after welcome the session's state arrived (docs/protocol.md, "Resynchronising"),
    // measured where the messages arrive, not where the page draws them.
    if (this.resync && msg.type === 'world_state' && this.resync.world_ms === null) {
      this.resync.world_ms = (this.now() - this.resync.t0_s) * 1000;
    }
    if (this.resync && msg.type === 'execution_progress' && msg.replay && this.resync.progress_ms === null) {
      this.resync.progress_ms = (this.now() - this.resync.t0_s) * 1000;
    }
    switch (msg.type) {
      case 'welcome':
        this.resync = { t0_s: this.now(), world_ms: null, progress_ms: null };
        this.session = msg.session;
        this.leaseHolder = msg.lease_holder ?? null;
        if (msg.heartbeat_period_s > 0) this.heartbeat_s = msg.heartbeat_period_s;
        if (msg.link_timeout_s > 0) this.timeout_s = msg.link_timeout_s;
        this.backoff_s = 0.25;
        this.startTimer();
        this.setState('up', `session ${msg.session}`);
        if (this.wantLease && this.leaseHolder === null) this.send('lease_request');
        break;
      case 'heartbeat':
        this.peerHeartbeat = { t_s: msg.t_s, received_s: this.now() };
        if (Number.isFinite(msg.echo_t_s)) {
          const rtt = this.now() - msg.echo_t_s - (msg.hold_s ?? 0);
          if (rtt >= 0 && rtt < 60) this.rtt_s = this.rtt_s === null ? rtt : 0.8 * this.rtt_s + 0.2 * rtt;
        }
        break;
      case 'lease_grant':
        this.leaseHolder = msg.holder ?? null;
        break;
      case 'lease_state':
        this.leaseHolder = msg.holder ?? null;
        // control left free (its holder went away): take it unless this page gave it up
        if (this.leaseHolder === null && this.wantLease) this.send('lease_request');
        break;
      case 'error':
        // the operator site answers the protocol's hello with an error (a service bug): the
        // welcome has come all the same, so this one is not shown as a problem
        if (msg.in_reply_to === this.helloSeq && msg.code === 'invalid_command') {
          console.warn(`operator refused hello: ${msg.message}`);
          return;
        }
        ++this.errorsReceived;
        this.lastError = msg;
        break;
      default:
        break;
    }
    this.emit(msg.type, msg);
    this.emit('*', msg);
  }

  checkSeq(seq, type) {
    const r = this.in.accept(seq);
    if (r === 'gap') this.emit('seq_gap', { seq, type });
    else if (r === 'duplicate' || r === 'invalid') this.emitLocalError(`operator sent ${type} with seq ${seq} (${r})`);
  }

  requestLease() { this.wantLease = true; return this.send('lease_request'); }
  releaseLease() { this.wantLease = false; return this.send('lease_release'); }
}

// The main thread's side of a Link running in a worker.
export class LinkProxy {
  constructor(url, { clientName = 'teachsim-web' } = {}) {
    this.url = url;
    this.clientName = clientName;
    this.listeners = new Map();
    Object.assign(this, { state: 'connecting', stateReason: '', session: null, leaseHolder: null, rtt_s: null,
                          reconnects: 0, errorsReceived: 0, open: false });
    this.worker = new Worker(new URL('./link_worker.js', import.meta.url), { type: 'module' });
    this.worker.onmessage = (e) => {
      const { event, msg, status } = e.data;
      if (status) Object.assign(this, status);
      if (event) this.emit(event, msg);
    };
    this.worker.onerror = (e) => this.emit('local_error', `the link worker failed: ${e.message ?? 'unknown error'}`);
  }

  on(type, fn) {
    if (!this.listeners.has(type)) this.listeners.set(type, []);
    this.listeners.get(type).push(fn);
  }

  emit(type, msg) {
    for (const fn of this.listeners.get(type) ?? []) {
      try { fn(msg); } catch (e) { console.error(`handler for ${type} failed`, e); if (type !== 'local_error') this.emit('local_error', `UI handler for ${type}: ${e.message}`); }
    }
    if (type !== 'link' && type !== 'local_error' && type !== 'seq_gap' && type !== 'camera_frame') {
      for (const fn of this.listeners.get('*') ?? []) fn(msg);
    }
  }

  holdsLease() { return this.session !== null && this.leaseHolder === this.session; }
  connect() { this.worker.postMessage({ op: 'connect', url: this.url, clientName: this.clientName }); }
  close() { this.worker.postMessage({ op: 'close' }); }
  // Returns whether the message was handed to an open link (its seq is assigned in the worker).
  send(type, fields = {}) {
    if (!this.open) return null;
    this.worker.postMessage({ op: 'send', type, fields });
    return true;
  }
  requestLease() { this.worker.postMessage({ op: 'requestLease' }); return true; }
  releaseLease() { this.worker.postMessage({ op: 'releaseLease' }); return true; }
}
