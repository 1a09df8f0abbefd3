// Everything on the page around the 3D view: the HUD, the gauges, the banner, the keys
// panel with thumbnails, the toolbar, toasts, the help and the end of the session.

const $ = (id) => document.getElementById(id);
const fmt = (x, d = 2) => (x === null || x === undefined ? '–' : Number(x).toFixed(d));

export class Hud {
  constructor(hello, link) {
    this.hello = hello;
    this.link = link;
    this.stopped = null;
    this.thumbs = new Map(); // "index label t" -> data URL
    this.wanted = []; // keys waiting for a thumbnail
    this.notices = [];
    $('key-btn').onclick = () => this.onKey();
    $('undo-btn').onclick = () => link.send({ type: 'undo' });
    $('pause-btn').onclick = () => this.togglePause();
    $('touch-btn').onclick = () => link.send({ type: 'touch', on: !this.frame?.touch });
    $('posonly-btn').onclick = () => link.send({ type: 'position_only', on: !this.frame?.position_only });
    $('release-btn').onclick = () => link.send({ type: 'release' });
    $('help-btn').onclick = () => this.toggleHelp();
    $('stop-btn').onclick = () => this.stop();
    $('help').onclick = () => this.hideHelp();
    if (localStorage.getItem('puppetcli-help-seen')) this.hideHelp();
    else setTimeout(() => this.hideHelp(), 8000);
    localStorage.setItem('puppetcli-help-seen', '1');
  }

  takeLabel() {
    const text = $('label').value.trim();
    $('label').value = '';
    return text;
  }

  togglePause() { this.link.send({ type: 'pause', on: !this.frame?.paused }); }
  toggleHelp() { $('help').classList.toggle('hidden'); }
  hideHelp() { $('help').classList.add('hidden'); }

  stop() {
    const quiet = new URLSearchParams(location.search).get('noconfirm') === '1';
    if (quiet || confirm('End the session? It is saved with its keys.')) this.link.send({ type: 'stop' });
  }

  update(frame, info) {
    this.frame = frame;
    const s = frame.stats, h = this.hello;
    const lat = this.link.latency();
    const mode = frame.grip ? `grip ${frame.grip.bone}` : frame.touch ? 'touch' : 'free';
    $('hud').textContent = [
      `${h.rig}  t = ${fmt(frame.t, 3)} s${frame.paused ? '  PAUSED' : ''}`,
      `real time ×${fmt(s.rtf)}   headroom ×${fmt(s.headroom, 1)}`,
      `${fmt(s.steps_per_s, 0)} steps/s of ${h.h * 1000} ms, ${fmt(s.step_us, 0)} µs a step`,
      `${s.solver}, ${s.rows} rows, ${s.contacts} contacts`,
      `input latency ${fmt(lat.p50, 0)} ms`,
      `mode: ${mode}, position-only ${frame.position_only ? 'on' : 'off'}`,
      info.pad ? `3D mouse: ${info.pad}` : '',
      s.rejected ? `rejected messages: ${s.rejected}` : '',
      this.link.connected ? '' : 'DISCONNECTED: retrying…',
    ].filter(Boolean).join('\n');
    this.gauge('force', frame.wrench.force, h.haptics.max_force, 'N', 1);
    this.gauge('torque', frame.wrench.torque, h.haptics.max_torque, 'N·m', 2);
    const slow = !frame.paused && (s.behind || s.rtf < 0.95);
    $('banner').hidden = !slow;
    if (slow) $('banner').textContent = `Physics slower than real time (×${fmt(s.rtf)}): the doll moves slowly`;
    $('pause-btn').textContent = frame.paused ? 'Resume (Space)' : 'Pause (Space)';
    $('touch-btn').textContent = `Touch: ${frame.touch ? 'on' : 'off'} (T)`;
    $('touch-btn').classList.toggle('on', frame.touch);
    $('posonly-btn').textContent = `Position only: ${frame.position_only ? 'on' : 'off'} (O)`;
  }

  gauge(name, v, max, unit, digits) {
    const size = Math.hypot(...v);
    const bar = $(`${name}-bar`);
    bar.style.width = `${Math.min(100, (100 * size) / max)}%`;
    bar.classList.toggle('clamped', size >= 0.999 * max);
    $(`${name}-num`).textContent = `${size.toFixed(digits)} ${unit}`;
  }

  keys(list) {
    this.list = list;
    const ol = $('key-list');
    ol.replaceChildren();
    for (const key of list) {
      const id = `${key.index} ${key.label} ${key.t}`;
      const li = document.createElement('li');
      const img = document.createElement('img');
      img.alt = key.label;
      if (this.thumbs.has(id)) img.src = this.thumbs.get(id);
      else this.wanted.push({ id, img });
      li.append(img, `${key.label}  (t = ${key.t.toFixed(3)} s)`);
      ol.append(li);
    }
  }

  // After a render: give the keys that wait for one a picture of the screen.
  fillThumbnails(view) {
    if (!this.wanted.length) return;
    const url = view.thumbnail();
    for (const { id, img } of this.wanted) { this.thumbs.set(id, url); img.src = url; }
    this.wanted = [];
  }

  notice(level, text) {
    this.notices.push(text);
    const div = document.createElement('div');
    div.className = `toast ${level}`;
    div.textContent = text;
    $('toasts').append(div);
    setTimeout(() => div.remove(), 4000);
  }

  end(msg) {
    this.stopped = msg;
    const lines = [`${msg.keys} keys. Session: ${msg.session}`, ...msg.outputs];
    $('stopped-text').replaceChildren(...lines.map((t) => Object.assign(document.createElement('div'), { textContent: t })));
    $('stopped').hidden = false;
  }

  onKey() { /* set by main */ }
}
