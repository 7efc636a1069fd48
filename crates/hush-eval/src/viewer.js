// hush's image comparison (see viewer.rs): decodes each view's half-float images and draws them on one
// canvas, tonemapped as the metrics are. No network, no external files.
"use strict";
(function () {
  // Half float bits to numbers, once for all 65536 values.
  const HALF = new Float32Array(65536);
  for (let h = 0; h < 65536; h++) {
    const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 31, f = h & 1023;
    HALF[h] = e === 0 ? s * f * Math.pow(2, -24) : e === 31 ? (f ? NaN : s * Infinity) : s * (1 + f / 1024) * Math.pow(2, e - 15);
  }
  // OIDN's filmic curve (Hable's, with training/color.py's constants) and sRGB: hush-eval's tonemap.rs.
  const A = 0.22, B = 0.3, C = 0.1, D = 0.2, E = 0.01, F = 0.3, WHITE = 11.2, SCALE = 1.758141;
  const hable = (x) => (x * (A * x + C * B) + D * E) / (x * (A * x + B) + D * F) - E / F;
  const HW = hable(WHITE);
  function tonemap(x) {
    if (!(x > 0)) return 0;
    if (x === Infinity) return 1;
    const y = Math.min(1, Math.max(0, hable(x * SCALE) / HW));
    return y <= 0.0031308 ? 12.92 * y : 1.055 * Math.pow(y, 1 / 2.4) - 0.055;
  }
  // The error colour scale: black, purple, orange, pale yellow (an approximation of "inferno").
  const STOPS = [[0, 0, 4], [87, 16, 110], [188, 55, 84], [249, 142, 9], [252, 255, 164]];
  function scale(t) {
    if (!(t >= 0)) t = t === t ? 0 : 1;
    t = Math.min(1, t) * (STOPS.length - 1);
    const i = Math.min(STOPS.length - 2, Math.floor(t)), f = t - i, a = STOPS[i], b = STOPS[i + 1];
    return [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])];
  }
  async function inflate(b64) {
    const raw = atob(b64), bytes = new Uint8Array(raw.length);
    for (let i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate"));
    return new Uint8Array(await new Response(stream).arrayBuffer());
  }
  async function decode(b64, n) {
    const planes = await inflate(b64);
    if (planes.length !== 2 * n) throw new Error("an image holds " + planes.length + " bytes, not " + 2 * n);
    const out = new Float32Array(n);
    for (let i = 0; i < n; i++) out[i] = HALF[planes[i] | (planes[n + i] << 8)];
    return out;
  }
  const fmt = (v) => (v === v ? (Math.abs(v) >= 1e4 || (v !== 0 && Math.abs(v) < 1e-3) ? v.toExponential(4) : v.toFixed(5)) : "NaN");

  let active = null; // the viewer the keys go to: the last one pointed at or clicked

  class Viewer {
    constructor(root, data, images) {
      this.root = root;
      this.data = data;
      this.images = images;
      this.w = data.width;
      this.h = data.height;
      this.ref = images.length - 1;
      const q = (c) => root.querySelector(c);
      this.canvas = q(".hv-canvas");
      this.ctx = this.canvas.getContext("2d");
      this.readout = q(".hv-readout");
      this.el = {
        mode: q(".hv-mode"), other: q(".hv-other"), split: q(".hv-split"), exposure: q(".hv-exposure"),
        ev: q(".hv-ev"), error: q(".hv-error"), max: q(".hv-max"), zoom: q(".hv-zoom"),
        bar: q(".hv-scale-bar"), mid: q(".hv-scale-mid"), top: q(".hv-scale-max"),
      };
      this.picks = Array.from(root.querySelectorAll(".hv-pick"));
      this.state = { pick: 0, mode: "single", other: this.ref, split: 0.5, ev: 0, error: "rel", max: 0.1 };
      this.fit();
      this.wire();
      this.pointer = null;
      this.sync();
    }
    fit() {
      const cw = this.canvas.width, ch = this.canvas.height;
      this.zoom = Math.min(cw / this.w, ch / this.h);
      this.ox = (cw - this.w * this.zoom) / 2;
      this.oy = (ch - this.h * this.zoom) / 2;
      this.fitZoom = this.zoom;
    }
    zoomAt(factor, cx, cy) {
      const z = Math.min(64, Math.max(this.fitZoom / 4, this.zoom * factor));
      const ix = (cx - this.ox) / this.zoom, iy = (cy - this.oy) / this.zoom;
      this.zoom = z;
      this.ox = cx - ix * z;
      this.oy = cy - iy * z;
      this.draw();
    }
    canvasPoint(ev) {
      const r = this.canvas.getBoundingClientRect();
      return [((ev.clientX - r.left) * this.canvas.width) / r.width, ((ev.clientY - r.top) * this.canvas.height) / r.height];
    }
    wire() {
      const el = this.el;
      this.picks.forEach((b) => b.addEventListener("click", () => this.set({ pick: +b.dataset.i })));
      el.mode.addEventListener("change", () => this.set({ mode: el.mode.value }));
      el.other.addEventListener("change", () => this.set({ other: +el.other.value }));
      el.split.addEventListener("input", () => this.set({ split: +el.split.value }));
      el.exposure.addEventListener("input", () => this.set({ ev: +el.exposure.value }));
      el.error.addEventListener("change", () => this.set({ error: el.error.value }));
      el.max.addEventListener("change", () => this.set({ max: +el.max.value }));
      this.root.querySelector(".hv-zoom-in").addEventListener("click", () => this.zoomAt(2, this.canvas.width / 2, this.canvas.height / 2));
      this.root.querySelector(".hv-zoom-out").addEventListener("click", () => this.zoomAt(0.5, this.canvas.width / 2, this.canvas.height / 2));
      this.root.querySelector(".hv-fit").addEventListener("click", () => { this.fit(); this.draw(); });
      const c = this.canvas;
      c.addEventListener("wheel", (ev) => {
        ev.preventDefault();
        const [x, y] = this.canvasPoint(ev);
        this.zoomAt(Math.pow(2, -ev.deltaY / 200), x, y);
      }, { passive: false });
      let drag = null;
      c.addEventListener("mousedown", (ev) => { drag = [ev.clientX, ev.clientY, this.ox, this.oy]; active = this; });
      window.addEventListener("mouseup", () => { drag = null; });
      window.addEventListener("mousemove", (ev) => {
        if (!drag) return;
        const r = c.getBoundingClientRect(), k = c.width / r.width;
        this.ox = drag[2] + (ev.clientX - drag[0]) * k;
        this.oy = drag[3] + (ev.clientY - drag[1]) * k;
        this.draw();
      });
      c.addEventListener("mousemove", (ev) => { this.pointer = this.canvasPoint(ev); active = this; this.read(); });
      c.addEventListener("mouseleave", () => { this.pointer = null; this.read(); });
      this.root.addEventListener("mouseenter", () => { active = this; });
      this.root.addEventListener("click", () => { active = this; });
    }
    set(change) {
      Object.assign(this.state, change);
      this.sync();
    }
    // Controls follow the state, then the picture and the readout.
    sync() {
      const s = this.state, el = this.el;
      this.picks.forEach((b, i) => {
        b.classList.toggle("on", i === s.pick);
        b.classList.toggle("right", s.mode === "split" && i === s.other);
      });
      el.mode.value = s.mode;
      el.other.value = String(s.other);
      el.split.value = String(s.split);
      el.exposure.value = String(s.ev);
      el.ev.textContent = (s.ev >= 0 ? "+" : "−") + Math.abs(s.ev).toFixed(2) + " EV";
      el.error.value = s.error;
      el.max.value = String(s.max);
      el.mid.textContent = String(+(s.max / 2).toPrecision(3));
      el.top.textContent = String(s.max);
      const bar = el.bar.getContext("2d");
      for (let x = 0; x < el.bar.width; x++) {
        const [r, g, b] = scale(x / (el.bar.width - 1));
        bar.fillStyle = "rgb(" + (r | 0) + "," + (g | 0) + "," + (b | 0) + ")";
        bar.fillRect(x, 0, 1, el.bar.height);
      }
      this.root.dataset.pick = this.images[s.pick].method;
      this.root.dataset.mode = s.mode;
      this.draw();
    }
    // The image index shown at canvas column cx.
    shownAt(cx) {
      const s = this.state;
      return s.mode === "split" && cx >= s.split * this.canvas.width ? s.other : s.pick;
    }
    draw() {
      const s = this.state, cw = this.canvas.width, ch = this.canvas.height;
      const out = this.ctx.createImageData(cw, ch), px = out.data;
      const exposure = this.data.exposure * Math.pow(2, s.ev), ref = this.images[this.ref].pixels;
      const splitX = s.mode === "split" ? s.split * cw : Infinity;
      for (let cy = 0; cy < ch; cy++) {
        const iy = Math.floor((cy + 0.5 - this.oy) / this.zoom);
        for (let cx = 0; cx < cw; cx++) {
          const o = 4 * (cy * cw + cx);
          const ix = Math.floor((cx + 0.5 - this.ox) / this.zoom);
          px[o + 3] = 255;
          if (ix < 0 || iy < 0 || ix >= this.w || iy >= this.h) {
            px[o] = px[o + 1] = px[o + 2] = 51;
            continue;
          }
          const p = 3 * (iy * this.w + ix), img = this.images[cx >= splitX ? s.other : s.pick].pixels;
          if (s.mode === "error") {
            let e = 0;
            for (let k = 0; k < 3; k++) {
              const d = s.error === "rel"
                ? Math.abs(img[p + k] - ref[p + k]) / (Math.abs(ref[p + k]) + 0.01)
                : Math.abs(tonemap(img[p + k] * exposure) - tonemap(ref[p + k] * exposure));
              e = d > e || d !== d ? d : e;
            }
            const c = scale(e / s.max);
            px[o] = c[0]; px[o + 1] = c[1]; px[o + 2] = c[2];
          } else {
            for (let k = 0; k < 3; k++) px[o + k] = Math.round(255 * tonemap(img[p + k] * exposure));
          }
        }
      }
      if (splitX < cw) {
        const x = Math.floor(splitX);
        for (let cy = 0; cy < ch; cy++) {
          const o = 4 * (cy * cw + x);
          px[o] = px[o + 1] = px[o + 2] = 255;
        }
      }
      this.ctx.putImageData(out, 0, 0);
      this.el.zoom.textContent = (this.zoom >= 1 ? this.zoom.toFixed(2) : this.zoom.toPrecision(2)) + " canvas px per pixel";
      this.read();
    }
    // The readout: the pixel under the pointer, its HDR value in the image shown there, and its error.
    read() {
      const r = this.readout;
      if (!this.pointer) {
        r.textContent = "Point at the image to read a pixel.";
        delete r.dataset.x;
        return;
      }
      const [cx, cy] = this.pointer;
      const ix = Math.floor((cx - this.ox) / this.zoom), iy = Math.floor((cy - this.oy) / this.zoom);
      if (ix < 0 || iy < 0 || ix >= this.w || iy >= this.h) {
        r.textContent = "Outside the image.";
        delete r.dataset.x;
        return;
      }
      const i = this.shownAt(cx), img = this.images[i], p = 3 * (iy * this.w + ix);
      const v = [0, 1, 2].map((k) => img.pixels[p + k]), ref = [0, 1, 2].map((k) => this.images[this.ref].pixels[p + k]);
      const rel = Math.max(...[0, 1, 2].map((k) => Math.abs(v[k] - ref[k]) / (Math.abs(ref[k]) + 0.01)));
      r.dataset.x = ix;
      r.dataset.y = iy;
      r.dataset.method = img.method;
      r.dataset.rgb = v.join(",");
      r.textContent = img.method + " at (" + ix + ", " + iy + "): R " + fmt(v[0]) + "  G " + fmt(v[1]) + "  B " + fmt(v[2]) +
        " (linear HDR); relative error against the reference " + fmt(rel);
    }
  }

  document.addEventListener("keydown", (ev) => {
    const v = active || viewers.find(Boolean);
    // Keys typed into a text field or a list are theirs; a slider keeps only its arrow keys.
    const t = ev.target, typing = t && (/^(SELECT|TEXTAREA)$/.test(t.tagName) || (t.tagName === "INPUT" && t.type !== "range"));
    if (!v || ev.ctrlKey || ev.metaKey || ev.altKey || typing) return;
    const k = ev.key, n = v.images.length;
    if (k >= "1" && k <= "9" && +k <= n - 1) v.set({ pick: +k - 1 });
    else if (k === "r") v.set({ pick: v.ref });
    else if (k === "s") v.set({ mode: "split" });
    else if (k === "e") v.set({ mode: "error" });
    else if (k === "o") v.set({ mode: "single" });
    else if (k === "+" || k === "=") v.zoomAt(2, v.canvas.width / 2, v.canvas.height / 2);
    else if (k === "-") v.zoomAt(0.5, v.canvas.width / 2, v.canvas.height / 2);
    else if (k === "0") { v.fit(); v.draw(); }
    else if (k === "[") v.set({ ev: Math.max(-10, v.state.ev - 0.5) });
    else if (k === "]") v.set({ ev: Math.min(10, v.state.ev + 0.5) });
    else return;
    ev.preventDefault();
  });

  const viewers = [];
  window.hushViewers = viewers;
  const roots = Array.from(document.querySelectorAll(".hush-viewer"));
  Promise.all(roots.map(async (root, index) => {
    const data = JSON.parse(root.querySelector(".hv-data").textContent);
    const n = 3 * data.width * data.height;
    const images = await Promise.all(data.images.map(async (im) => ({ method: im.method, pixels: await decode(im.data, n) })));
    viewers[index] = new Viewer(root, data, images);
    root.dataset.ready = "1";
  })).then(() => { document.body.dataset.viewers = "ready"; }, (e) => {
    document.body.dataset.viewers = "failed";
    console.error("hush viewer: " + e);
  });
})();
