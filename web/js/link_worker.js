// Runs the operator link (link.js) off the page's main thread, so that heartbeats keep their
// 20 Hz while the page renders; events go to the page with the link's status attached.
import { Link } from './link.js';

let link = null;

function post(event, msg) {
  const transfer = event === 'camera_frame' ? [msg.pixels.buffer] : [];
  postMessage({ event, msg, status: link.status() }, transfer);
}

self.onmessage = (e) => {
  const m = e.data;
  if (m.op === 'connect' && !link) {
    link = new Link(m.url, { clientName: m.clientName });
    link.sink = post;
    link.connect();
    setInterval(() => postMessage({ status: link.status() }), 200);
  } else if (!link) {
    // nothing to do before connect
  } else if (m.op === 'send') link.send(m.type, m.fields);
  else if (m.op === 'requestLease') link.requestLease();
  else if (m.op === 'releaseLease') link.releaseLease();
  else if (m.op === 'close') link.close();
};
