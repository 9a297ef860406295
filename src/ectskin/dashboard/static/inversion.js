// ectskin live dashboard: the physical inversion on the Contact panel (loaded before app.js,
// which calls window.ectskinInversion.build(meta, svgs) when it draws the faces and
// .update(frame) on every frame). No dependencies.
//
// A frame's "inversion" (ectskin.live.output.InversionFrame; docs/live.md) holds the fingers
// fitted through the twin's response field, no trained model: per finger its face, whether it
// presses ("contact": true) or hovers, u, v (mm), force (N) or height (mm), and their standard
// errors (the Cramér–Rao bound at the fit; null where not finite: unresolved). On each face, in
// the face's own (u, v) mm like every drawing there (SVG y = -v), a finger is a diamond at its
// fitted point, filled when it presses and hollow when it hovers, inside an ellipse of
// semi-axes u_se_mm across and v_se_mm along (one standard error). A finger whose point has a
// null SE is not drawn. The side panel lists the count, each point ± SE, force ± SE (pressing)
// or height ± SE (hovering), whether the fit converged and started warm, and its time.
// A message without an inversion draws nothing and says why: no key at all (an engine from
// before the inversion), or null (before the reference; with --inversion-every N > 1 the last
// fit stands for the N frames from its own, the frames it was fitted for).
(function () {
  "use strict";

  const SVG_NS = "http://www.w3.org/2000/svg";
  const SLOTS = 2;                // the inversion fits at most two fingers
  const MARK_MM = 1.8;            // the diamond's half-diagonal, mm on the face

  const view = {
    enabled: false,               // the engine runs the inversion head (meta.inversion)
    every: 1,                     // the head fits every every-th frame
    faces: {},                    // face -> {ellipses: [SLOTS], marks: [SLOTS]}
    shown: null,                  // {seq, inv}: the fit drawn now, or null
  };

  const $ = (id) => document.getElementById(id);
  const isNum = (v) => typeof v === "number" && isFinite(v);
  function svgEl(tag, attrs, parent) {
    const el = document.createElementNS(SVG_NS, tag);
    for (const k in attrs) el.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(el);
    return el;
  }
  function setText(el, text) { if (el.textContent !== text) el.textContent = text; }

  // Decimals for a value and its standard error: the SE to two significant digits (at most 3
  // decimals), the value to the same; 2 without a positive SE.
  function seDigits(se) {
    if (!isNum(se) || se <= 0) return 2;
    return Math.max(0, Math.min(3, 1 - Math.floor(Math.log10(se))));
  }
  // "v ± se" (the SE's own decimals); "v ± — (SE not finite)" without a finite SE.
  function withSe(v, se) {
    if (!isNum(v)) return "—";
    if (!isNum(se)) return v.toFixed(2) + " ± — (SE not finite)";
    const d = seDigits(se);
    return v.toFixed(d) + " ± " + se.toFixed(d);
  }
  // A finger's point is drawn when it and both its standard errors are finite.
  function resolved(f) {
    return !!f && isNum(f.u_mm) && isNum(f.v_mm) && isNum(f.u_se_mm) && isNum(f.v_se_mm) &&
      f.u_se_mm >= 0 && f.v_se_mm >= 0;
  }

  // The drawings on each face's SVG (over the learned model's fingers) and the panel's rows.
  function build(meta, svgs) {
    const inv = meta && meta.inversion;
    view.enabled = !!inv;
    view.every = inv && Number.isInteger(inv.every) && inv.every >= 1 ? inv.every : 1;
    view.faces = {};
    view.shown = null;
    const panel = $("inversion");
    panel.hidden = !view.enabled;
    const rows = $("inv-fingers");
    rows.innerHTML = "";
    document.querySelectorAll("#contact-panel .inv-legend").forEach((el) => {
      el.hidden = !view.enabled;
    });
    if (!view.enabled) return;
    for (const face in svgs) {
      const g = svgEl("g", { class: "inv-layer", "data-face": face }, svgs[face]);
      const ellipses = [], marks = [];
      for (let k = 0; k < SLOTS; k++) {
        ellipses.push(svgEl("ellipse", { class: "inv-se", "data-finger": k, rx: 0, ry: 0,
                                         visibility: "hidden" }, g));
      }
      for (let k = 0; k < SLOTS; k++) {
        marks.push(svgEl("path", { class: "inv-mark", "data-finger": k, d: "",
                                   visibility: "hidden" }, g));
      }
      view.faces[face] = { ellipses, marks };
    }
    for (let k = 0; k < SLOTS; k++) {
      const row = document.createElement("div");
      row.className = "inv-row absent";
      row.dataset.finger = k;
      row.innerHTML = '<span class="name"></span><span class="where"></span>' +
        '<span class="what"></span>';
      row.querySelector(".name").textContent = "inv. " + (k + 1);
      rows.appendChild(row);
    }
    draw(null, "waiting for frames");
  }

  // The inversion a frame shows: its own, the last fit while it stands for this frame, or none.
  function update(f) {
    if (!view.enabled || !f) return;
    if (!Object.prototype.hasOwnProperty.call(f, "inversion")) {
      view.shown = null;
      draw(null, "this engine sends no inversion (a version from before it)");
      return;
    }
    const inv = f.inversion;
    if (inv && typeof inv === "object") {
      view.shown = { seq: f.seq, inv };
      draw(view.shown, "");
      return;
    }
    // the hub's newest fit (it rides on frames without one, since frames between are skipped)
    const carried = f.inversion_fit;
    let last = view.shown;
    if (carried && typeof carried === "object" && isNum(carried.seq) && carried.inversion &&
        typeof carried.inversion === "object" && (!last || !isNum(last.seq) || carried.seq > last.seq)) {
      last = { seq: carried.seq, inv: carried.inversion };
      view.shown = last;
    }
    if (last && view.every > 1 && isNum(f.seq) && isNum(last.seq) && f.seq > last.seq &&
        f.seq - last.seq < view.every) {
      draw(last, "the fit of frame " + last.seq + " (one every " + view.every + " frames)");
      return;
    }
    view.shown = null;
    draw(null, "no inversion for this frame (no reference yet" +
      (view.every > 1 ? ", or a frame between fits)" : ")"));
  }

  function draw(shown, note) {
    const inv = shown ? shown.inv : null;
    const fingers = inv && Array.isArray(inv.fingers) ? inv.fingers : [];
    const count = $("inv-count");
    const n = inv && Number.isInteger(inv.n_fingers) ? inv.n_fingers : null;
    count.dataset.count = n === null ? "" : String(n);
    setText(count, n === null ? "—" : String(n));
    const fit = $("inv-fit");
    fit.dataset.converged = inv ? String(!!inv.converged) : "";
    fit.dataset.warm = inv ? String(!!inv.warm) : "";
    fit.dataset.fitMs = inv && isNum(inv.fit_ms) ? String(inv.fit_ms) : "";
    setText(fit, !inv ? "" : (inv.converged ? "converged" : "NOT converged") + ", " +
      (inv.warm ? "warm start" : "cold start") + ", fit " +
      (isNum(inv.fit_ms) ? inv.fit_ms.toFixed(2) : "—") + " ms");
    fit.classList.toggle("warn", !!inv && !inv.converged);
    let unresolved = 0;
    for (const face in view.faces) {
      const fv = view.faces[face];
      for (let k = 0; k < SLOTS; k++) {
        const f = fingers[k];
        const here = resolved(f) && f.face === face;
        const ell = fv.ellipses[k], mark = fv.marks[k];
        ell.setAttribute("visibility", here ? "visible" : "hidden");
        mark.setAttribute("visibility", here ? "visible" : "hidden");
        if (!here) continue;
        const x = f.u_mm, y = -f.v_mm, d = MARK_MM;
        const pressing = f.contact !== false;
        ell.setAttribute("cx", String(x));
        ell.setAttribute("cy", String(y));
        ell.setAttribute("rx", String(f.u_se_mm));   // across: u
        ell.setAttribute("ry", String(f.v_se_mm));   // along: v (SVG y = -v)
        mark.setAttribute("d", "M" + x + "," + (y - d) + "L" + (x + d) + "," + y + "L" + x +
          "," + (y + d) + "L" + (x - d) + "," + y + "Z");
        for (const el of [ell, mark]) {
          el.classList.toggle("hovering", !pressing);
          el.dataset.u = String(f.u_mm);
          el.dataset.v = String(f.v_mm);
        }
      }
    }
    $("inv-fingers").querySelectorAll(".inv-row").forEach((row, k) => {
      const f = k < fingers.length ? fingers[k] : null;
      const ok = resolved(f);
      if (f && !ok) unresolved += 1;
      const pressing = !!f && f.contact !== false;
      row.classList.toggle("absent", !f);
      row.dataset.face = f ? String(f.face) : "";
      row.dataset.mode = !f ? "" : pressing ? "pressing" : "hovering";
      row.dataset.drawn = ok && String(f.face) in view.faces ? "1" : "";
      setText(row.querySelector(".where"), !f ? "" : String(f.face) + (ok
        ? " u " + withSe(f.u_mm, f.u_se_mm) + ", v " + withSe(f.v_mm, f.v_se_mm) + " mm"
        : ": point not resolved (SE not finite), not drawn"));
      setText(row.querySelector(".what"), !f ? "" : pressing
        ? "pressing " + withSe(f.force_n, f.force_se_n) + " N"
        : "hovering " + withSe(f.height_mm, f.height_se_mm) + " mm above");
    });
    const extra = fingers.length > SLOTS ? fingers.length - SLOTS : 0;
    const parts = [];
    if (note) parts.push(note);
    if (unresolved) parts.push(unresolved + " finger(s) with a point not resolved: not drawn");
    if (extra) parts.push(extra + " more finger(s) not shown");
    const el = $("inv-note");
    el.dataset.state = !inv ? "none" : shown && note ? "held" : "drawn";
    setText(el, parts.join("; "));
  }

  window.ectskinInversion = { build, update, view, seDigits, withSe };
})();
