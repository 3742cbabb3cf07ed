/** Creating SVG elements, and the colours of vehicle types. */

export const SVG_NS = "http://www.w3.org/2000/svg";

/**
 * A new SVG element with attributes (values are stringified; null/undefined skipped).
 * @param {string} tag
 * @param {Record<string, unknown>} [attrs]
 * @param {Element} [parent] appended to it when given
 */
export function svgEl(tag, attrs = {}, parent = undefined) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (value !== null && value !== undefined) node.setAttribute(key, String(value));
  }
  if (parent) parent.appendChild(node);
  return node;
}

/** A titled element: a <title> child shows as a tooltip and is read by screen readers. */
export function withTitle(node, text) {
  let title = node.querySelector("title");
  if (!title) title = svgEl("title", {}, node);
  title.textContent = text;
  return node;
}

/** Okabe-Ito colours (distinguishable with common colour-vision deficiencies). */
const PALETTE = ["#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#7f6d00", "#000000"];

/** Colour of each vehicle type, in the order of the sorted type names. */
export function typeColors(types) {
  const colors = new Map();
  [...types].sort().forEach((type, i) => {
    colors.set(type, i < PALETTE.length ? PALETTE[i] : `hsl(${(i * 67) % 360} 65% 40%)`);
  });
  return colors;
}

/** A number with at most `digits` significant digits, without trailing zeros. */
export function fmt(value, digits = 4) {
  if (value === null || value === undefined || !Number.isFinite(value)) return "–";
  if (value === 0) return "0";
  const magnitude = Math.abs(value);
  if (magnitude >= 10 ** digits) return Math.round(value).toLocaleString("en-US");
  if (magnitude < 1e-3) return value.toExponential(2);
  return String(Number(value.toPrecision(digits)));
}
