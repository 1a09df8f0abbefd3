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
    $('release-btn').onclick = () => this.onRelease();
    $('unpin-btn').onclick = () => link.send({ type: 'unpin' });
    $('help-btn').onclick = () => this.toggleHelp();
    $('stop-btn').onclick = () => this.stop();
    // A clicked button gives the focus back, so Space / Enter stay shortcuts (not a second click).
    for (const b of document.querySelectorAll('button')) b.addEventListener('click', () => b.blur());
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
    const lat = this.link.median(50), rtt = this.link.rtt;
    const mode = frame.grip ? `grip ${frame.grip.bone}` : frame.touch ? 'touch' : 'free';
    $('hud').textContent = [
      `${h.rig}  t = ${fmt(frame.t, 3)} s${frame.paused ? '  PAUSED' : ''}`,
      `real time ×${fmt(s.rtf)}   headroom ×${fmt(s.headroom, 1)}`,
      `${fmt(s.steps_per_s, 0)} steps/s of ${h.h * 1000} ms, ${fmt(s.step_us, 0)} µs a step`,
      `${s.solver}, ${s.rows} rows, ${s.contacts} contacts`,
      `input latency ${fmt(lat, 0)} ms (median of 50)${rtt === null ? '' : `, socket ${fmt(rtt, 0)} ms`}`,
      `mode: ${mode}, position-only ${frame.position_only ? 'on' : 'off'}`,
      info.pad ? `3D mouse: ${info.pad}` : '',
      s.rejected ? `rejected messages: ${s.rejected}` : '',
    ].filter(Boolean).join('\n');
    const w = frame.wrench;
    this.gauge('force', w.force, w.requested_force, h.haptics.max_force, 'N', 1);
    this.gauge('torque', w.torque, w.requested_torque, h.haptics.max_torque, 'N·m', 2);
    const slow = !frame.paused && (s.behind || s.rtf < 0.95);
    $('banner').hidden = !slow;
    if (slow) $('banner').textContent = `Physics slower than real time (×${fmt(s.rtf)}): the doll moves slowly`;
    $('pause-btn').textContent = frame.paused ? 'Resume (Space)' : 'Pause (Space)';
    $('touch-btn').textContent = `Touch: ${frame.touch ? 'on' : 'off'} (T)`;
    $('touch-btn').classList.toggle('on', frame.touch);
    $('posonly-btn').textContent = `Position only: ${frame.position_only ? 'on' : 'off'} (O)`;
  }

  // A bar |v| / max that turns red at the clamp (the device displays less than requested).
  gauge(name, v, requested, max, unit, digits) {
    const size = Math.hypot(...v);
    const wanted = requested ? Math.hypot(...requested) : size;
    const bar = $(`${name}-bar`);
    bar.style.width = `${Math.min(100, (100 * size) / max)}%`;
    bar.classList.toggle('clamped', size >= 0.999 * max || wanted > max * 1.001);
    $(`${name}-num`).textContent = `${size.toFixed(digits)} ${unit}`;
  }

  // The keys panel. fresh: the list follows a change made now (a key taken), so a key without
  // a picture gets the next rendered view; the list of a hello (a reload, a reconnect) has
  // keys taken earlier, whose pose is not on screen any more: they get no picture.
  keys(list, fresh = true) {
    this.list = list;
    this.wanted = [];
    const ul = $('key-list');
    ul.replaceChildren();
    for (const key of list) {
      const id = `${key.index} ${key.label} ${key.t}`;
      const li = document.createElement('li');
      let pic = document.createElement('img');
      pic.alt = key.label;
      if (this.thumbs.has(id)) pic.src = this.thumbs.get(id);
      else if (fresh) this.wanted.push({ id, img: pic });
      else pic = Object.assign(document.createElement('div'), { className: 'nopic', textContent: 'no picture' });
      const index = Object.assign(document.createElement('b'), { textContent: `#${key.index} ` });
      li.append(pic, index, `${key.label}  (t = ${Number(key.t).toFixed(3)} s)`);
      ul.append(li);
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

  // The session is over: say where it was saved and take no more input.
  end(msg) {
    this.stopped = msg;
    const line = (t, tag = 'div') => Object.assign(document.createElement(tag), { textContent: t });
    const outputs = document.createElement('ul');
    outputs.append(...(msg.outputs || []).map((t) => line(t, 'li')));
    $('stopped-text').replaceChildren(line(`Session saved to ${msg.session} (${msg.keys} keys)`), outputs);
    $('stopped').hidden = false;
    this.hideHelp();
    for (const el of document.querySelectorAll('button, input')) el.disabled = true;
  }

  // The HUD's own mark of the connection (the page also shows a "disconnected" box).
  connection(up) {
    $('hud').classList.toggle('offline', !up);
  }

  onKey() { /* set by main */ }
  onRelease() { /* set by main */ }
}
