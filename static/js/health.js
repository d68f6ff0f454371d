// The loop-health light in the header: the server's verdict on the last 10 s of loop timing
// (GET /api/status -> loop.health; the limits are the server's, app/control/loop_health.py).
// The page only shows it: a coloured dot, the figures, and the reasons in the tooltip.

import { fixed } from "./api.js";

const WORDS = {
  green: "healthy", amber: "near a limit", red: "past a limit", unknown: "not measured yet",
};
let shown = "";

export function renderHealth(s) {
  const light = s.loop && s.loop.health;
  const el = document.getElementById("loop-health");
  if (!el || !light) return;
  // short, so the header stays one line on a laptop: rate · p99 lateness · overruns
  const text = light.level === "unknown" ? "● –" :
    `● ${fixed(light.rate_hz, 0)} Hz · p99 ${fixed(light.p99_ms, light.p99_ms < 10 ? 2 : 0)} ms · ` +
    `${light.overruns} ovr`;
  const title = [
    `Loop health over the last ${fixed(light.window_s, 0)} s: ${light.level} (${WORDS[light.level]})`,
    `rate ${fixed(light.rate_hz, 1)} of ${fixed(light.target_hz, 0)} Hz (${fixed(light.rate_share * 100, 1)} %)`,
    `lateness p99 ${fixed(light.p99_ms, 3)} ms; longest pause between ticks ${fixed(light.longest_gap_ms, 1)} ms`,
    `overruns ${light.overruns} of ${light.ticks} ticks (${fixed(light.overrun_share * 100, 2)} %)`,
    ...light.reasons,
    "red: over 1 % overruns, a pause over 20 ms or under 95 % of the rate; amber: halfway",
  ].join("\n");
  const key = `${light.level}|${text}|${title}`;
  if (key === shown) return; // no layout work when nothing changed
  shown = key;
  el.textContent = text;
  el.title = title;
  el.className = `health health-${light.level}`;
  el.dataset.level = light.level;
}
