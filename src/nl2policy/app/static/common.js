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
async function domains() { if (!DOMAINS) DOMAINS = await api("GET", "/api/domains"); return DOMAINS; }
function isQuestion(domain, id) { return id && DOMAINS[domain].questions[id] !== undefined; }
function label(domain, id) { return DOMAINS[domain].questions[id] || DOMAINS[domain].actions[id] || id; }
