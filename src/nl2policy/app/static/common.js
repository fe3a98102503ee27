// Shared helpers for the three pages: JSON calls that surface the API's error messages.
async function api(method, url, body) {
  const res = await fetch(url, {method, headers: {"Content-Type": "application/json"},
                                body: body === undefined ? undefined : JSON.stringify(body)});
  const data = await res.json().catch(() => ({}));
  if (!res.ok) {
    let d = data.detail;
    let msg = typeof d === "string" ? d : (d && d.error) || (d && d.message) ||
              (Array.isArray(d) ? d.map(e => `${(e.loc || []).slice(1).join(".")}: ${e.msg}`).join("; ") : res.statusText);
    throw new Error(msg);
  }
  return data;
}
function $(sel) { return document.querySelector(sel); }
function el(tag, attrs = {}, text) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}
function confidenceBadge(c) {
  const cls = c >= 0.8 ? "high" : c >= 0.5 ? "mid" : "low";
  return `<span class="badge ${cls}" id="confidence">confidence ${(100 * c).toFixed(0)}%</span>`;
}
let DOMAINS = null;
// The domains come from the server (each domain's folder names its title): every domain menu on
// the page is filled from them, so a new domain needs no page edited.
async function domains() {
  if (!DOMAINS) {
    DOMAINS = await api("GET", "/api/domains");
    for (const sel of document.querySelectorAll("select#domain")) {
      if (sel.options.length) continue;
      for (const [id, d] of Object.entries(DOMAINS)) sel.appendChild(el("option", {value: id}, d.title || id));
    }
  }
  return DOMAINS;
}
// A learned test that no dictionary question names, "raw:gap_ahead<0.2281" (trees/raw.py), read
// in the feature's units: "Is the gap to the car ahead in my lane less than 22.8 m?".
function rawTest(domain, id) {
  const m = /^raw:([A-Za-z_][A-Za-z0-9_]*)([<>])([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)$/.exec(id || "");
  const unit = m && (DOMAINS[domain].units || {})[m[1]];
  return unit ? {unit, greater: m[2] === ">", value: parseFloat(m[3])} : null;
}
function isQuestion(domain, id) { return !!id && (DOMAINS[domain].questions[id] !== undefined || rawTest(domain, id) !== null); }
function label(domain, id) {
  const raw = rawTest(domain, id);
  if (raw) {
    // 3 significant digits, halves up, no exponent: trees/raw.py's three_digits writes the same
    const amount = String(Number((raw.value * raw.unit.scale).toPrecision(3))) + (raw.unit.unit ? ` ${raw.unit.unit}` : "");
    return `Is ${raw.unit.name} ${raw.greater ? "more" : "less"} than ${amount}?`;
  }
  return DOMAINS[domain].questions[id] || DOMAINS[domain].actions[id] || id;
}

// Markdown as formatted text (headings, paragraphs, lists, **bold**, *italic*, `code`): enough
// for the corpus briefing, escaped first so nothing in it runs as HTML.
function escapeHtml(s) { return String(s).replace(/[&<>"']/g, c => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"}[c])); }
function inlineMarkdown(s) {
  return escapeHtml(s).replace(/`([^`]+)`/g, "<code>$1</code>").replace(/\*\*([^*]+)\*\*/g, "<b>$1</b>").replace(/\*([^*]+)\*/g, "<i>$1</i>");
}
function markdown(text) {
  const out = []; let list = null, para = [];
  const flush = () => { if (para.length) { out.push(`<p>${inlineMarkdown(para.join(" "))}</p>`); para = []; } };
  const endList = () => { if (list) { out.push(`</${list}>`); list = null; } };
  for (const line of text.split("\n")) {
    const h = line.match(/^(#{1,4})\s+(.*)/), ul = line.match(/^\s*[-*]\s+(.*)/), ol = line.match(/^\s*\d+[.)]\s+(.*)/);
    if (h) { flush(); endList(); const n = Math.min(h[1].length + 1, 4); out.push(`<h${n}>${inlineMarkdown(h[2])}</h${n}>`); }
    else if (ul || ol) {
      flush(); const kind = ul ? "ul" : "ol";
      if (list !== kind) { endList(); out.push(`<${kind}>`); list = kind; }
      out.push(`<li>${inlineMarkdown((ul || ol)[1])}</li>`);
    } else if (!line.trim()) { flush(); endList(); }
    else if (list) out[out.length - 1] = out[out.length - 1].replace(/<\/li>$/, ` ${inlineMarkdown(line.trim())}</li>`);
    else para.push(line.trim());
  }
  flush(); endList();
  return out.join("\n");
}

// A grid slot in words: slot 0 is the first question; slot s is the "yes" (odd) or "no" (even)
// answer to the question in slot (s - 1) / 2.
function answerOf(slot) { return slot % 2 ? "yes" : "no"; }
function slotPlace(domain, grid, slot) {
  if (slot === 0) return "the first question";
  const parent = Math.floor((slot - 1) / 2);
  return grid[parent] ? `the “${answerOf(slot)}” answer to “${label(domain, grid[parent])}”` : `the “${answerOf(slot)}” box below`;
}
function seconds(s) {
  if (s === null || s === undefined) return "";
  s = Math.round(s);
  return s < 60 ? `${s} s` : `${Math.floor(s / 60)} min ${String(s % 60).padStart(2, "0")} s`;
}
