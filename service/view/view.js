// The live view: a plan view of the tracks, fed by GET /api/v1/stream (server-sent events).
// Plain JavaScript, no dependencies. World coordinates are metres, x east, y north.
"use strict";

(function () {
  const TRAIL_POINTS = 40; // positions kept per track, client-side
  const EXTENDED_TRAIL_POINTS = 12; // an extended track's centroid: a short trail
  const VECTOR_SECONDS = 10; // a velocity vector shows where the track is in this many seconds
  const PICK_PIXELS = 12; // a click this close to a track selects it
  const DRAG_PIXELS = 4; // a press that moves less than this is a click

  const canvas = document.getElementById("plan");
  const ctx = canvas.getContext("2d");
  const el = (id) => document.getElementById(id);

  // what the latest frame holds, and what is kept across frames
  const model = {
    seq: null,
    time: null,
    confirmed: [],
    tentative: [],
    detections: [], // flat [x0, y0, x1, y1, ...]
    trails: new Map(), // id -> [[x, y], ...]
    selected: null, // id of the clicked track
    frames: 0,
    patterns: {}, // point_patterns.patterns of the configuration: name -> [[x, y], ...]
  };

  // screen = (offsetX + x * scale, offsetY - y * scale), in CSS pixels
  const view = { scale: 0.01, offsetX: 0, offsetY: 0, userMoved: false };

  const toScreen = (x, y) => [view.offsetX + x * view.scale, view.offsetY - y * view.scale];
  const toWorld = (sx, sy) => [(sx - view.offsetX) / view.scale, (view.offsetY - sy) / view.scale];

  // -- drawing, one small function per track kind -------------------------------------------

  function drawVelocity(t, sx, sy, color) {
    const [ex, ey] = toScreen(
      t.position[0] + t.velocity[0] * VECTOR_SECONDS,
      t.position[1] + t.velocity[1] * VECTOR_SECONDS,
    );
    ctx.strokeStyle = color;
    ctx.beginPath();
    ctx.moveTo(sx, sy);
    ctx.lineTo(ex, ey);
    ctx.stroke();
    const angle = Math.atan2(ey - sy, ex - sx);
    if (Math.hypot(ex - sx, ey - sy) > 6) {
      ctx.beginPath();
      ctx.moveTo(ex, ey);
      ctx.lineTo(ex - 6 * Math.cos(angle - 0.4), ey - 6 * Math.sin(angle - 0.4));
      ctx.lineTo(ex - 6 * Math.cos(angle + 0.4), ey - 6 * Math.sin(angle + 0.4));
      ctx.closePath();
      ctx.fillStyle = color;
      ctx.fill();
    }
  }

  function drawTrail(t, color, points = TRAIL_POINTS) {
    const whole = model.trails.get(t.id);
    if (!whole || whole.length < 2) return;
    const trail = whole.slice(-points);
    ctx.strokeStyle = color;
    ctx.lineWidth = 1;
    ctx.beginPath();
    trail.forEach(([x, y], i) => {
      const [sx, sy] = toScreen(x, y);
      if (i === 0) ctx.moveTo(sx, sy);
      else ctx.lineTo(sx, sy);
    });
    ctx.stroke();
  }

  // an individual target: a dot, its velocity vector, its trail and its id
  function drawIndividual(t, style) {
    const [sx, sy] = toScreen(t.position[0], t.position[1]);
    ctx.globalAlpha = style.alpha;
    drawTrail(t, style.trail);
    ctx.lineWidth = 1.5;
    // a tentative track's velocity comes from two or three detections, often a pair of false
    // alarms read as a fast target: its vector would only clutter the picture
    if (style.label) drawVelocity(t, sx, sy, style.color);
    ctx.fillStyle = style.color;
    ctx.beginPath();
    ctx.arc(sx, sy, style.radius, 0, 2 * Math.PI);
    ctx.fill();
    if (style.selected) {
      ctx.strokeStyle = "#ffffff";
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.arc(sx, sy, style.radius + 5, 0, 2 * Math.PI);
      ctx.stroke();
    }
    if (style.label) {
      ctx.fillStyle = style.color;
      ctx.font = "12px system-ui, sans-serif";
      ctx.fillText(t.id, sx + 7, sy - 7);
    }
    ctx.globalAlpha = 1;
  }

  // the extent of an extended track in world terms: semi-axes (m) and the major axis's angle
  // (rad, counter-clockwise from +x, y north); from `semi_axes`/`orientation`, or else from
  // the eigenvectors of `matrix` (the ellipse (p - c)' X^-1 (p - c) <= 1)
  function extentAxes(extent) {
    if (!extent) return null;
    const axes = extent.semi_axes;
    if (Array.isArray(axes) && axes.length === 2 && Number.isFinite(extent.orientation)) {
      return { major: axes[0], minor: axes[1], angle: extent.orientation };
    }
    const m = extent.matrix;
    if (!Array.isArray(m) || m.length !== 2) return null;
    const [a, b, c] = [m[0][0], m[0][1], m[1][1]];
    const mean = (a + c) / 2;
    const root = Math.hypot((a - c) / 2, b);
    return {
      major: Math.sqrt(Math.max(mean + root, 0)),
      minor: Math.sqrt(Math.max(mean - root, 0)),
      angle: 0.5 * Math.atan2(2 * b, a - c),
    };
  }

  // the extent ellipse on the screen: centre, semi-axes in CSS pixels, and the rotation the
  // canvas takes (its y axis points down, so a counter-clockwise world angle is negated)
  function screenEllipse(t) {
    const axes = extentAxes(t.extent);
    if (!axes) return null;
    const [sx, sy] = toScreen(t.position[0], t.position[1]);
    return {
      sx,
      sy,
      rx: Math.max(axes.major * view.scale, 1),
      ry: Math.max(axes.minor * view.scale, 1),
      rotation: -axes.angle,
    };
  }

  // whether the screen point (px, py) is inside a screen ellipse
  function insideEllipse(e, px, py) {
    const dx = px - e.sx;
    const dy = py - e.sy;
    const cos = Math.cos(e.rotation);
    const sin = Math.sin(e.rotation);
    const u = (dx * cos + dy * sin) / e.rx; // along the major axis
    const v = (-dx * sin + dy * cos) / e.ry; // along the minor axis
    return u * u + v * v <= 1;
  }

  // a point-pattern track: its likeliest pattern's points at the track's attitude
  // (point p is seen at position + R(attitude) p), joined in order
  function drawPattern(t, style) {
    const shapes = t.shape_probabilities;
    if (!shapes || !Number.isFinite(t.attitude)) return;
    let best = null;
    for (const name of Object.keys(shapes)) if (best === null || shapes[name] > shapes[best]) best = name;
    const points = model.patterns[best];
    if (!Array.isArray(points)) return;
    const c = Math.cos(t.attitude);
    const s = Math.sin(t.attitude);
    const at = points.map(([px, py]) =>
      toScreen(t.position[0] + c * px - s * py, t.position[1] + s * px + c * py));
    ctx.strokeStyle = style.color;
    ctx.beginPath();
    at.forEach(([sx, sy], i) => (i ? ctx.lineTo(sx, sy) : ctx.moveTo(sx, sy)));
    ctx.closePath();
    ctx.stroke();
    for (const [sx, sy] of at) ctx.strokeRect(sx - 3, sy - 3, 6, 6);
  }

  // an extended object or group: its extent ellipse (outline, faint fill), the centroid with
  // its id and velocity vector, and a short trail of the centroid
  function drawExtended(t, style) {
    const e = screenEllipse(t);
    if (!e) {
      drawIndividual(t, style);
      return;
    }
    ctx.globalAlpha = style.alpha;
    drawTrail(t, style.trail, EXTENDED_TRAIL_POINTS);
    ctx.beginPath();
    ctx.ellipse(e.sx, e.sy, e.rx, e.ry, e.rotation, 0, 2 * Math.PI);
    ctx.fillStyle = style.fill;
    ctx.fill();
    ctx.strokeStyle = style.selected ? "#ffffff" : style.color;
    ctx.lineWidth = style.selected ? 2.5 : 1.5;
    ctx.stroke();
    ctx.lineWidth = 1.5;
    drawPattern(t, style);
    drawVelocity(t, e.sx, e.sy, style.color);
    ctx.fillStyle = style.color;
    ctx.beginPath();
    ctx.arc(e.sx, e.sy, style.radius - 1, 0, 2 * Math.PI);
    ctx.fill();
    if (style.label) {
      ctx.font = "12px system-ui, sans-serif";
      ctx.fillText(t.id, e.sx + 7, e.sy - 7);
    }
    ctx.globalAlpha = 1;
  }

  // any kind this page does not know yet: a hollow square at its position
  function drawOther(t, style) {
    const [sx, sy] = toScreen(t.position[0], t.position[1]);
    ctx.globalAlpha = style.alpha;
    ctx.strokeStyle = style.color;
    ctx.lineWidth = 1.5;
    ctx.strokeRect(sx - 5, sy - 5, 10, 10);
    if (style.label) {
      ctx.fillStyle = style.color;
      ctx.fillText(`${t.id} (${t.kind})`, sx + 7, sy - 7);
    }
    ctx.globalAlpha = 1;
  }

  // the screen points of a formation's members that this frame holds, by id
  function memberPoints(t) {
    const byId = new Map(model.confirmed.concat(model.tentative).map((m) => [m.id, m]));
    const out = [];
    for (const id of t.members || []) {
      const m = byId.get(id);
      if (m) out.push(toScreen(m.position[0], m.position[1]));
    }
    return out;
  }

  // the convex hull of screen points (monotone chain), counter-clockwise on screen
  function hull(points) {
    const p = points.slice().sort((a, b) => a[0] - b[0] || a[1] - b[1]);
    if (p.length < 3) return p;
    const cross = (o, a, b) => (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    const lower = [];
    for (const q of p) {
      while (lower.length >= 2 && cross(lower[lower.length - 2], lower[lower.length - 1], q) <= 0) lower.pop();
      lower.push(q);
    }
    const upper = [];
    for (const q of p.slice().reverse()) {
      while (upper.length >= 2 && cross(upper[upper.length - 2], upper[upper.length - 1], q) <= 0) upper.pop();
      upper.push(q);
    }
    return lower.slice(0, -1).concat(upper.slice(0, -1));
  }

  // a formation: its outline (the hull of its members, a few pixels out), each member joined
  // to the formation's centre, the centre with its id and velocity vector (the members are
  // drawn as the individual tracks they are)
  function drawFormation(t, style) {
    const [cx, cy] = toScreen(t.position[0], t.position[1]);
    const members = memberPoints(t);
    ctx.globalAlpha = style.alpha;
    drawTrail(t, style.trail, EXTENDED_TRAIL_POINTS);
    ctx.strokeStyle = style.selected ? "#ffffff" : style.color;
    ctx.lineWidth = style.selected ? 2.5 : 1.5;
    const outline = hull(members).map(([sx, sy]) => {
      const d = Math.hypot(sx - cx, sy - cy) || 1;
      return [sx + (8 * (sx - cx)) / d, sy + (8 * (sy - cy)) / d];
    });
    if (outline.length >= 3) {
      ctx.beginPath();
      outline.forEach(([sx, sy], i) => (i ? ctx.lineTo(sx, sy) : ctx.moveTo(sx, sy)));
      ctx.closePath();
      ctx.fillStyle = style.fill;
      ctx.fill();
      ctx.stroke();
    }
    ctx.lineWidth = 1;
    ctx.setLineDash([4, 3]);
    ctx.beginPath();
    for (const [sx, sy] of members) {
      ctx.moveTo(cx, cy);
      ctx.lineTo(sx, sy);
    }
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.lineWidth = 1.5;
    drawVelocity(t, cx, cy, style.color);
    ctx.fillStyle = style.color;
    ctx.fillRect(cx - style.radius, cy - style.radius, 2 * style.radius, 2 * style.radius);
    if (style.label) {
      ctx.font = "12px system-ui, sans-serif";
      ctx.fillText(`${t.id} (${members.length})`, cx + 7, cy + 14);
    }
    ctx.globalAlpha = 1;
  }

  // by track kind
  const DRAW_KIND = { individual: drawIndividual, extended: drawExtended, formation: drawFormation };

  // colours by track kind (and status); a kind not here takes the individual's
  const PALETTE = {
    individual: {
      confirmed: { color: "#5fb8ff", trail: "#2f6d9c", fill: "rgba(95, 184, 255, 0.12)" },
      tentative: { color: "#9aa7b5", trail: "#56606b", fill: "rgba(154, 167, 181, 0.08)" },
    },
    extended: {
      confirmed: { color: "#e07ce8", trail: "#8e4a94", fill: "rgba(224, 124, 232, 0.14)" },
      tentative: { color: "#b79ab9", trail: "#6b5a6d", fill: "rgba(183, 154, 185, 0.08)" },
    },
    formation: {
      confirmed: { color: "#7be38f", trail: "#3f8a4d", fill: "rgba(123, 227, 143, 0.10)" },
      tentative: { color: "#a5c9ad", trail: "#5b7561", fill: "rgba(165, 201, 173, 0.06)" },
    },
  };

  // where a click lands on a drawn track: its screen geometry, for picking and for tests
  function screenShape(t) {
    if (t.kind === "extended") {
      const e = screenEllipse(t);
      if (e) return e;
    }
    if (t.kind === "formation") {
      const [sx, sy] = toScreen(t.position[0], t.position[1]);
      return { sx, sy, members: memberPoints(t).length };
    }
    const [sx, sy] = toScreen(t.position[0], t.position[1]);
    return { sx, sy };
  }

  function drawTrack(t, style) {
    (DRAW_KIND[t.kind] || drawOther)(t, style);
  }

  function niceStep(metres) {
    const p = Math.pow(10, Math.floor(Math.log10(metres)));
    for (const m of [1, 2, 5, 10]) if (m * p >= metres) return m * p;
    return 10 * p;
  }

  function formatMetres(m) {
    return m >= 1000 ? `${m / 1000} km` : `${m} m`;
  }

  function drawGrid(w, h) {
    const step = niceStep(80 / view.scale);
    const [x0, y1] = toWorld(0, 0);
    const [x1, y0] = toWorld(w, h);
    ctx.strokeStyle = "#1f2a36";
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (let x = Math.ceil(x0 / step) * step; x <= x1; x += step) {
      const [sx] = toScreen(x, 0);
      ctx.moveTo(Math.round(sx) + 0.5, 0);
      ctx.lineTo(Math.round(sx) + 0.5, h);
    }
    for (let y = Math.ceil(y0 / step) * step; y <= y1; y += step) {
      const [, sy] = toScreen(0, y);
      ctx.moveTo(0, Math.round(sy) + 0.5);
      ctx.lineTo(w, Math.round(sy) + 0.5);
    }
    ctx.stroke();
    const scaleBar = el("scale");
    scaleBar.style.width = `${step * view.scale}px`;
    scaleBar.textContent = formatMetres(step);
  }

  const screenTracks = []; // what was drawn, for picking and for tests

  function render() {
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    const dpr = window.devicePixelRatio || 1;
    if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
      canvas.width = Math.round(w * dpr);
      canvas.height = Math.round(h * dpr);
    }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, w, h);
    drawGrid(w, h);

    if (el("show-detections").checked) {
      ctx.fillStyle = "#f0b95a";
      const d = model.detections;
      for (let i = 0; i + 1 < d.length; i += 2) {
        const [sx, sy] = toScreen(d[i], d[i + 1]);
        ctx.fillRect(sx - 1.5, sy - 1.5, 3, 3);
      }
    }

    screenTracks.length = 0;
    const showTentative = el("show-tentative").checked;
    const drawn = showTentative ? model.tentative.concat(model.confirmed) : model.confirmed;
    for (const t of drawn) {
      const confirmed = t.status === "confirmed";
      const colours = (PALETTE[t.kind] || PALETTE.individual)[confirmed ? "confirmed" : "tentative"];
      drawTrack(t, {
        alpha: confirmed ? 1 : 0.35,
        color: colours.color,
        trail: colours.trail,
        fill: colours.fill,
        radius: confirmed ? 4 : 3,
        label: confirmed,
        selected: t.id === model.selected,
      });
      screenTracks.push({ id: t.id, kind: t.kind, status: t.status, ...screenShape(t) });
    }
    publishState(drawn);
  }

  // -- what a test (or a curious user) can read -----------------------------------------------

  function publishState(drawn) {
    const list = el("track-list");
    const ids = drawn.map((t) => t.id).join(",");
    if (list.dataset.ids !== ids) {
      list.dataset.ids = ids;
      list.replaceChildren(
        ...drawn.map((t) => {
          const li = document.createElement("li");
          li.textContent = t.id;
          li.dataset.trackId = t.id;
          li.dataset.status = t.status;
          li.dataset.kind = t.kind;
          return li;
        }),
      );
    }
    window.viewState = {
      seq: model.seq,
      time: model.time,
      frames: model.frames,
      selected: model.selected,
      scale: view.scale,
      offsetX: view.offsetX,
      offsetY: view.offsetY,
      // {id, kind, status, sx, sy}: CSS pixels in the canvas; extended tracks add their
      // ellipse's semi-axes rx, ry (CSS pixels) and the canvas's rotation (rad, clockwise)
      tracks: screenTracks.slice(),
      detections: model.detections.length / 2,
    };
  }

  let pending = false;
  function requestRender() {
    if (!pending) {
      pending = true;
      requestAnimationFrame(() => {
        pending = false;
        render();
      });
    }
  }

  // -- details of the clicked track -----------------------------------------------------------

  function fmt(v, digits) {
    return typeof v === "number" && Number.isFinite(v) ? v.toFixed(digits) : "–";
  }

  function findTrack(id) {
    return model.confirmed.find((t) => t.id === id) || model.tentative.find((t) => t.id === id);
  }

  // rows the details panel adds by track kind
  const DETAIL_KIND = {
    extended(t) {
      const axes = extentAxes(t.extent);
      return [
        [
          "semi-axes",
          axes ? `${fmt(axes.major, 1)}, ${fmt(axes.minor, 1)} m` : "–",
        ],
        ["orientation", axes ? `${fmt((axes.angle * 180) / Math.PI, 1)}°` : "–"],
        ["detections", String((t.detection_ids || []).length)],
      ];
    },
    formation(t) {
      return [["members", (t.members || []).join(", ")]];
    },
  };

  function showDetails() {
    const box = el("details");
    if (model.selected === null) {
      box.hidden = true;
      delete box.dataset.trackId;
      return;
    }
    const t = findTrack(model.selected);
    box.hidden = false;
    box.dataset.trackId = model.selected;
    el("details-id").textContent = model.selected;
    const rows = [];
    if (!t) {
      box.dataset.status = "gone";
      rows.push(["status", "no longer live"]);
    } else {
      box.dataset.status = t.status;
      const speed = Math.hypot(t.velocity[0], t.velocity[1]);
      rows.push(
        ["status", t.status],
        ["kind", t.kind],
        ["id", t.id],
        ["position", `${fmt(t.position[0], 1)}, ${fmt(t.position[1], 1)} m`],
        ["velocity", `${fmt(t.velocity[0], 1)}, ${fmt(t.velocity[1], 1)} m/s`],
        ["speed", `${fmt(speed, 1)} m/s`],
        ["score", fmt(t.score, 2)],
        ["hits", String(t.hits)],
      );
      if (DETAIL_KIND[t.kind]) rows.push(...DETAIL_KIND[t.kind](t));
      if (t.formation_id) rows.push(["formation", t.formation_id]);
      for (const [mode, p] of Object.entries(t.model_probabilities || {})) {
        rows.push([`p(${mode})`, fmt(p, 3)]);
      }
    }
    const dl = el("details-fields");
    dl.replaceChildren(
      ...rows.flatMap(([k, v]) => {
        const dt = document.createElement("dt");
        dt.textContent = k;
        const dd = document.createElement("dd");
        dd.textContent = v;
        dd.dataset.field = k;
        return [dt, dd];
      }),
    );
  }

  el("details-close").addEventListener("click", () => {
    model.selected = null;
    showDetails();
    requestRender();
  });

  // -- frames from the service ----------------------------------------------------------------

  function fit() {
    const pts = [];
    for (const t of model.confirmed.concat(model.tentative)) {
      pts.push(t.position);
      const axes = t.kind === "extended" ? extentAxes(t.extent) : null;
      if (axes) {
        const [x, y] = t.position;
        pts.push([x - axes.major, y - axes.major], [x + axes.major, y + axes.major]);
      }
    }
    const d = model.detections;
    for (let i = 0; i + 1 < d.length; i += 2) pts.push([d[i], d[i + 1]]);
    if (pts.length === 0) return false;
    let [xmin, ymin, xmax, ymax] = [Infinity, Infinity, -Infinity, -Infinity];
    for (const [x, y] of pts) {
      xmin = Math.min(xmin, x);
      xmax = Math.max(xmax, x);
      ymin = Math.min(ymin, y);
      ymax = Math.max(ymax, y);
    }
    const w = canvas.clientWidth || 800;
    const h = canvas.clientHeight || 600;
    const span = Math.max(xmax - xmin, ymax - ymin, 100);
    view.scale = (0.85 * Math.min(w, h)) / span;
    view.offsetX = w / 2 - ((xmin + xmax) / 2) * view.scale;
    view.offsetY = h / 2 + ((ymin + ymax) / 2) * view.scale;
    return true;
  }

  function onFrame(frame) {
    const report = frame.report;
    model.frames += 1;
    model.seq = report.seq;
    model.time = report.time;
    model.confirmed = report.tracks || [];
    model.tentative = frame.tentative || [];
    model.detections = frame.detections || [];
    const live = new Set();
    for (const t of model.confirmed.concat(model.tentative)) {
      live.add(t.id);
      let trail = model.trails.get(t.id);
      if (!trail) model.trails.set(t.id, (trail = []));
      const last = trail[trail.length - 1];
      if (!last || last[0] !== t.position[0] || last[1] !== t.position[1]) {
        trail.push([t.position[0], t.position[1]]);
        if (trail.length > TRAIL_POINTS) trail.shift();
      }
    }
    for (const id of model.trails.keys()) if (!live.has(id)) model.trails.delete(id);
    if (!view.userMoved && model.frames <= 50) fit(); // until there is enough to frame
    el("seq").textContent = String(report.seq);
    el("time").textContent = report.time === null ? "–" : report.time.toFixed(2);
    el("n-confirmed").textContent = String(model.confirmed.length);
    el("n-tentative").textContent = String(model.tentative.length);
    el("n-detections").textContent = String(model.detections.length / 2);
    showDetails();
    requestRender();
  }

  // the reference patterns, for drawing point-pattern tracks: read at start and every 15 s
  function loadPatterns() {
    fetch("/api/v1/config")
      .then((r) => (r.ok ? r.json() : null))
      .then((doc) => {
        const p = doc && doc.point_patterns && doc.point_patterns.patterns;
        if (p && typeof p === "object") model.patterns = p;
      })
      .catch(() => {});
  }
  loadPatterns();
  setInterval(loadPatterns, 15000);

  function connect() {
    const status = el("status");
    const source = new EventSource("/api/v1/stream");
    source.addEventListener("report", (e) => {
      status.textContent = "live";
      status.dataset.state = "live";
      onFrame(JSON.parse(e.data));
    });
    source.addEventListener("error", () => {
      status.textContent = "reconnecting…";
      status.dataset.state = "lost";
    });
  }

  // -- pan (drag), zoom (wheel), select (click) -----------------------------------------------

  let drag = null;

  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY, ox: view.offsetX, oy: view.offsetY, moved: false };
    canvas.setPointerCapture(e.pointerId);
  });

  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x;
    const dy = e.clientY - drag.y;
    if (!drag.moved && Math.hypot(dx, dy) < DRAG_PIXELS) return;
    drag.moved = true;
    canvas.classList.add("dragging");
    view.offsetX = drag.ox + dx;
    view.offsetY = drag.oy + dy;
    view.userMoved = true;
    requestRender();
  });

  canvas.addEventListener("pointerup", (e) => {
    if (!drag) return;
    const wasClick = !drag.moved;
    drag = null;
    canvas.classList.remove("dragging");
    if (wasClick) select(e);
  });

  canvas.addEventListener("pointercancel", () => {
    drag = null;
    canvas.classList.remove("dragging");
  });

  function select(e) {
    const rect = canvas.getBoundingClientRect();
    const px = e.clientX - rect.left;
    const py = e.clientY - rect.top;
    let best = null;
    let bestDist = PICK_PIXELS;
    for (const t of screenTracks) {
      const dist = Math.hypot(t.sx - px, t.sy - py);
      // a confirmed track wins over a tentative one at the same distance
      if (dist < bestDist || (dist === bestDist && t.status === "confirmed")) {
        best = t;
        bestDist = dist;
      }
    }
    if (!best) {
      // no dot or centroid near: the smallest extent ellipse around the click, confirmed first
      let bestArea = Infinity;
      for (const t of screenTracks) {
        if (t.rx === undefined || !insideEllipse(t, px, py)) continue;
        const area = t.rx * t.ry * (t.status === "confirmed" ? 1 : 1e6);
        if (area < bestArea) {
          best = t;
          bestArea = area;
        }
      }
    }
    model.selected = best ? best.id : null;
    showDetails();
    requestRender();
  }

  canvas.addEventListener(
    "wheel",
    (e) => {
      e.preventDefault();
      const rect = canvas.getBoundingClientRect();
      const px = e.clientX - rect.left;
      const py = e.clientY - rect.top;
      const [wx, wy] = toWorld(px, py);
      const factor = Math.exp(-e.deltaY * 0.0015);
      view.scale = Math.min(1e3, Math.max(1e-6, view.scale * factor));
      view.offsetX = px - wx * view.scale; // the point under the cursor stays put
      view.offsetY = py + wy * view.scale;
      view.userMoved = true;
      requestRender();
    },
    { passive: false },
  );

  el("fit").addEventListener("click", () => {
    view.userMoved = false;
    fit();
    requestRender();
  });
  el("show-tentative").addEventListener("change", requestRender);
  el("show-detections").addEventListener("change", requestRender);
  window.addEventListener("resize", requestRender);

  render();
  connect();
})();
