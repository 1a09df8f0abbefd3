// The WebSocket to the server: JSON messages, an increasing seq on every input message,
// reconnection, and the input-to-screen latency of pointer messages.

export class Link {
  constructor(onMessage, onState) {
    this.onMessage = onMessage;
    this.onState = onState;
    this.seq = 0;
    this.sent = new Map(); // seq -> performance.now() of pointer messages
    this.acked = 0; // newest acked seq not yet shown on screen
    this.samples = [];
    this.connected = false;
    this.stopped = false;
    this.rtt = null; // ms, the last ping's round trip
    const token = new URLSearchParams(location.search).get('token') || '';
    const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
    this.url = `${scheme}://${location.host}/ws?token=${encodeURIComponent(token)}`;
    this.open();
    setInterval(() => this.send({ type: 'ping', t: performance.now() }, false), 2000);
  }

  open() {
    const ws = new WebSocket(this.url);
    ws.onopen = () => {
      this.connected = true;
      this.sent.clear(); // a new connection acks from scratch
      this.acked = 0;
      this.onState(true);
    };
    ws.onmessage = (e) => {
      const msg = JSON.parse(e.data);
      if (msg.type === 'frame' && msg.ack > this.acked) this.acked = msg.ack;
      if (msg.type === 'pong' && typeof msg.t === 'number') this.rtt = performance.now() - msg.t;
      if (msg.type === 'stopped') this.stopped = true;
      this.onMessage(msg);
    };
    ws.onclose = () => {
      this.connected = false;
      this.onState(false);
      if (!this.stopped) setTimeout(() => this.open(), 2000);
    };
    ws.onerror = () => {}; // onclose follows and retries
    this.ws = ws;
  }

  send(message, numbered = true) {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return false;
    if (numbered) {
      this.seq += 1;
      message.seq = this.seq;
      if (message.type === 'pointer') this.sent.set(this.seq, performance.now());
    }
    this.ws.send(JSON.stringify(message));
    return true;
  }

  // Called after a frame is drawn: the newest acked pointer message has reached the screen.
  shown() {
    if (!this.acked) return;
    const now = performance.now();
    let newest = -1;
    for (const seq of this.sent.keys()) if (seq <= this.acked && seq > newest) newest = seq;
    if (newest >= 0) {
      this.samples.push(now - this.sent.get(newest));
      if (this.samples.length > 200) this.samples.shift();
    }
    for (const seq of [...this.sent.keys()]) if (seq <= this.acked) this.sent.delete(seq);
  }

  // The median of the last n latency samples (the HUD's figure), or null.
  median(n = 50) {
    const s = this.samples.slice(-n).sort((a, b) => a - b);
    return s.length ? s[Math.floor(s.length / 2)] : null;
  }

  latency() {
    const s = [...this.samples].sort((a, b) => a - b);
    const at = (q) => (s.length ? s[Math.min(s.length - 1, Math.floor(q * s.length))] : null);
    return { count: s.length, p50: at(0.5), p95: at(0.95), last: this.samples.at(-1) ?? null };
  }
}
