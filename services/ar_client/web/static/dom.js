// Building page elements without HTML strings (nothing a server or a file says is ever parsed as
// markup) and without inline styles (the Content Security Policy forbids them).

export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k === "class") node.className = v;
    else if (k === "text") node.textContent = v;
    else node.setAttribute(k, v === true ? "" : String(v));
  }
  for (const c of children) if (c !== null && c !== undefined && c !== false) node.append(c);
  return node;
}

export const $ = (id) => document.getElementById(id);

// Plain text with a little markdown (blank-line paragraphs, "# " headings, "- " or "* " list items)
// as elements: the consent form as the study runner wrote it.
export function plainTextBlocks(text) {
  const out = [];
  for (const block of String(text || "").split(/\n\s*\n/)) {
    const lines = block.split("\n").map((l) => l.trim()).filter((l) => l);
    if (!lines.length) continue;
    if (lines.every((l) => /^[-*]\s+/.test(l))) {
      out.push(el("ul", {}, ...lines.map((l) => el("li", { text: l.replace(/^[-*]\s+/, "") }))));
    } else if (lines.length === 1 && /^#{1,3}\s+/.test(lines[0])) {
      out.push(el("h2", { text: lines[0].replace(/^#{1,3}\s+/, "") }));
    } else {
      out.push(el("p", { text: lines.join(" ") }));
    }
  }
  return out;
}
