/* VTD-SLAM dashboard: shared helpers (REST calls, errors in words, formatting, DOM, live job updates). */
"use strict";
const VTD = (() => {
  const API = "/api/v1";
  const TOKEN_KEY = "vtd-api-token";

  class ApiError extends Error {
    constructor(status, code, message, detail) { super(message); this.status = status; this.code = code; this.detail = detail; }
  }

  function authHeaders() {
    const t = localStorage.getItem(TOKEN_KEY);
    return t ? { Authorization: "Bearer " + t } : {};
  }

  /** Turn any failed response body into an ApiError with the api's own words. */
  function errorFrom(status, text) {
    let body = null;
    try { body = JSON.parse(text); } catch (_) { /* not JSON */ }
    const e = body && body.error;
    if (e && e.message) return new ApiError(status, e.code, e.message, e.detail);
    if (status === 0) return new ApiError(0, "network", "The server could not be reached. Is `vtdslam serve` running?");
    return new ApiError(status, "http_" + status, `The server answered ${status} ${text ? "(" + text.slice(0, 120) + ")" : ""}`);
  }

  async function api(path, { method = "GET", json, text = false, retryAuth = true } = {}) {
    const headers = { ...authHeaders() };
    if (json !== undefined) headers["Content-Type"] = "application/json";
    let res;
    try {
      res = await fetch(API + path, { method, headers, body: json === undefined ? undefined : JSON.stringify(json) });
    } catch (_) { throw errorFrom(0, ""); }
    if (res.status === 401 && retryAuth && askToken()) return api(path, { method, json, text, retryAuth: false });
    if (!res.ok) throw errorFrom(res.status, await res.text());
    if (res.status === 204) return null;
    return text ? res.text() : res.json();
  }

  /** The server sets VTD_API_TOKEN: ask once, keep it in this browser. */
  function askToken() {
    const t = prompt("This server needs an API token for changes (VTD_API_TOKEN). Token:");
    if (!t) return false;
    localStorage.setItem(TOKEN_KEY, t.trim());
    return true;
  }

  /** An error as readable sentences: the message, then field-level details if any. */
  function showError(box, err, prefix) {
    if (!box) return;
    box.replaceChildren();
    if (!err) { box.hidden = true; return; }
    box.append((prefix ? prefix + ": " : "") + (err.message || String(err)));
    const d = err.detail;
    const items = [];
    if (Array.isArray(d)) {
      for (const x of d) if (x && x.msg) items.push((x.loc || []).filter((p) => p !== "body").join(".") + ": " + x.msg);
    } else if (d && typeof d === "object") {
      for (const [k, v] of Object.entries(d)) {
        if (["errors", "problems", "missing", "allowed"].includes(k) && Array.isArray(v)) items.push(k + ": " + v.join(", "));
      }
    }
    if (items.length) { const ul = el("ul"); for (const i of items.slice(0, 12)) ul.append(el("li", {}, i)); box.append(ul); }
    box.hidden = false;
  }

  function toast(msg, ms = 3500) {
    const t = document.getElementById("toast");
    if (!t) return;
    t.textContent = msg; t.hidden = false;
    clearTimeout(toast.timer); toast.timer = setTimeout(() => { t.hidden = true; }, ms);
  }

  /** el("a", {href: "/x", class: "y"}, "text", child) */
  function el(tag, attrs = {}, ...children) {
    const n = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (v === undefined || v === null || v === false) continue;
      if (k === "class") n.className = v;
      else if (k.startsWith("on")) n.addEventListener(k.slice(2), v);
      else if (k === "text") n.textContent = v;
      else n.setAttribute(k, v === true ? "" : v);
    }
    for (const c of children) if (c !== null && c !== undefined && c !== false) n.append(c);
    return n;
  }

  const isNum = (x) => typeof x === "number" && isFinite(x);
  /** A number with its unit, or an em dash. */
  function num(x, digits = 3, unit = "") {
    if (!isNum(x)) return "—";
    const s = Math.abs(x) >= 1e4 ? Math.round(x).toLocaleString("en") : x.toFixed(digits);
    return unit ? s + " " + unit : s;
  }
  /** Metres, switched to millimetres or centimetres when small. */
  function metres(x) {
    if (!isNum(x)) return "—";
    const a = Math.abs(x);
    if (a < 0.01) return (x * 1000).toFixed(1) + " mm";
    if (a < 1) return (x * 100).toFixed(2) + " cm";
    return x.toFixed(3) + " m";
  }
  function bytes(n) {
    if (!isNum(n)) return "—";
    const u = ["B", "KB", "MB", "GB", "TB"]; let i = 0;
    while (n >= 1000 && i < u.length - 1) { n /= 1000; i++; }
    return (i ? n.toFixed(1) : n) + " " + u[i];
  }
  function seconds(s) {
    if (!isNum(s)) return "—";
    if (s < 60) return s.toFixed(s < 10 ? 1 : 0) + " s";
    const m = Math.floor(s / 60), r = Math.round(s % 60);
    if (m < 60) return `${m} min ${r} s`;
    return `${Math.floor(m / 60)} h ${m % 60} min`;
  }
  function when(iso) {
    if (!iso) return "—";
    const d = new Date(iso.endsWith("Z") || iso.includes("+") ? iso : iso + "Z");
    return d.toLocaleString(undefined, { dateStyle: "medium", timeStyle: "short" });
  }
  const parseTime = (iso) => (iso ? Date.parse(iso.endsWith("Z") || iso.includes("+") ? iso : iso + "Z") : NaN);
  /** Run time of a job: finished - started, or so far while running. */
  function jobDuration(job) {
    const s = parseTime(job.started_at);
    if (!isFinite(s)) return NaN;
    const e = job.finished_at ? parseTime(job.finished_at) : Date.now();
    return (e - s) / 1000;
  }
  const TERMINAL = new Set(["succeeded", "failed", "cancelled"]);
  const statusBadge = (s) => el("span", { class: "badge st-" + s }, s);
  const shortId = (id) => el("code", { class: "id", title: id }, id.slice(0, 8));

  /** What is left of a running job: "about 12 s left" while frames are tracked (the api's eta_s: the frames
   *  left at the rate so far), "frames done, finishing…" once they are (dense map, evaluation, saving: no
   *  estimate, rather than "0.0 s left" for as long as they take); "" otherwise. A live session's stream is
   *  open while its stage is "live" (storage.live.STREAMING_STAGE): all its received frames processed means
   *  caught up and waiting for more, not finishing (its stage says "finishing" once the stream ended). */
  function etaText(job) {
    if (job.status !== "running") return "";
    if (job.stage === "live") {
      const of = `${job.frames_done} of ${job.frames_total} received frames processed`;
      return job.frames_done >= job.frames_total ? `caught up: ${of}, waiting for frames` : of;
    }
    if (job.frames_total > 0 && job.frames_done >= job.frames_total) return "frames done, finishing…";
    return isNum(job.eta_s) ? `about ${seconds(job.eta_s)} left` : "";
  }

  function progressCell(job) {
    if (job.status === "succeeded") return document.createTextNode(`${job.frames_total} frames`);
    if (job.status === "queued") return document.createTextNode("waiting for a worker");
    if (job.status !== "running") return document.createTextNode(job.frames_total ? `stopped at frame ${job.frames_done} of ${job.frames_total}` : "");
    const eta = etaText(job) ? ", " + etaText(job) : "";
    return el("span", {}, el("progress", { max: 1, value: job.progress || 0 }), " ",
      el("span", { class: "num small" }, `${Math.round(100 * (job.progress || 0))} % · ${job.stage || ""} · ${job.frames_done}/${job.frames_total} frames${eta}`));
  }

  /**
   * Follow a job live: Server-Sent Events when available, polling otherwise (or after the stream fails).
   * onJob(job) on each change; returns a stop function.
   */
  function followJob(id, onJob, { pollMs = 2000 } = {}) {
    let stopped = false, es = null, timer = null;
    const poll = async () => {
      if (stopped) return;
      try { const j = await api("/jobs/" + id); onJob(j); if (TERMINAL.has(j.status)) return; } catch (_) { /* try again */ }
      timer = setTimeout(poll, pollMs);
    };
    if ("EventSource" in window) {
      es = new EventSource(`${API}/jobs/${id}/events`);
      es.addEventListener("progress", (ev) => { try { onJob(JSON.parse(ev.data)); } catch (_) { /* ignore */ } });
      es.addEventListener("end", () => { es.close(); es = null; api("/jobs/" + id).then(onJob, () => {}); });
      es.addEventListener("deleted", () => { es.close(); es = null; });
      es.onerror = () => { if (es && es.readyState === EventSource.CLOSED) { es = null; poll(); } };
    } else poll();
    return () => { stopped = true; if (es) es.close(); clearTimeout(timer); };
  }

  /**
   * Wide tables scroll sideways inside their card (.scroll); where one does not fit, say so: a "scroll sideways"
   * note above it and a fade at the edge still hiding columns (classes overflowing / at-end). Kept up to date
   * as rows arrive, the window resizes and the table is scrolled; hidden again when the table fits.
   */
  function scrollHints() {
    const hints = new Map();
    const update = (box) => {
      const hint = hints.get(box);
      const over = box.scrollWidth > box.clientWidth + 1;
      box.classList.toggle("overflowing", over);
      box.classList.toggle("at-end", over && box.scrollLeft + box.clientWidth >= box.scrollWidth - 1);
      if (hint) hint.hidden = !over;
    };
    const boxOf = (n) => (n instanceof Element ? n : n.parentElement)?.closest(".scroll");
    const sized = new ResizeObserver((entries) => { for (const e of entries) { const b = boxOf(e.target); if (b) update(b); } });
    const changed = new MutationObserver((records) => { for (const b of new Set(records.map((r) => boxOf(r.target)))) if (b) update(b); });
    for (const box of document.querySelectorAll(".scroll")) {
      const hint = el("div", { class: "scroll-hint", "aria-hidden": "true", hidden: true }, "scroll sideways for more →");
      box.before(hint);
      hints.set(box, hint);
      box.addEventListener("scroll", () => update(box), { passive: true });
      sized.observe(box);
      for (const child of box.children) sized.observe(child); // the table widens as its rows arrive
      changed.observe(box, { childList: true, subtree: true, characterData: true, attributes: true, attributeFilter: ["hidden"] });
      update(box);
    }
  }
  if ("ResizeObserver" in window && "MutationObserver" in window) scrollHints();

  return { API, ApiError, api, showError, toast, el, num, metres, bytes, seconds, when, jobDuration, TERMINAL,
    statusBadge, shortId, progressCell, etaText, followJob, authHeaders, askToken, errorFrom, isNum };
})();
