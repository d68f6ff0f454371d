// The tool and the wrist as the page knows them (/api/info's tool_offset_m and wrist): what
// is shown only with a wrist ([data-wrist]) or a tool offset ([data-tool]), the wrist angle
// and the tool offset beside the position. Nothing about the wrist shows without one.

import { deg, mm } from "./api.js";
import { setText } from "./ui.js";

export const PHI_STEP_DEG = 5; // one phi jog (key press or pad click) turns the wrist this far

// enabled: a wrist is fitted; minRad/maxRad its limits [rad]; offsetM the tool tip in the
// platform frame at phi = 0 [m]
export const wrist = { enabled: false, minRad: null, maxRad: null, offsetM: [0, 0, 0] };

export const hasTool = () => wrist.offsetM.some((v) => v !== 0);

// ``phiRad`` [rad] inside the wrist's limits.
export function clampPhi(phiRad) {
  return Math.min(Math.max(phiRad, wrist.minRad), wrist.maxRad);
}

// The wrist angle a new goal keeps [rad]: the wrist's goal, else where it is; 0 without one.
export function currentPhiRad(s) {
  if (!wrist.enabled || !s) return 0;
  const goal = s.goal && s.goal.phi_rad;
  if (goal !== null && goal !== undefined) return goal;
  return s.ee && Number.isFinite(s.ee.phi_rad) ? s.ee.phi_rad : 0;
}

// ``w``: /api/info's wrist ({enabled, min_rad, max_rad}) or null: the record only.
export function setWrist(w) {
  wrist.enabled = Boolean(w && w.enabled);
  if (wrist.enabled) {
    wrist.minRad = w.min_rad;
    wrist.maxRad = w.max_rad;
  }
}

export function startWrist(info) {
  setWrist(info && info.wrist);
  if (info && Array.isArray(info.tool_offset_m)) wrist.offsetM = info.tool_offset_m;
  document.querySelectorAll("[data-wrist]").forEach((el) => { el.hidden = !wrist.enabled; });
  document.querySelectorAll("[data-tool]").forEach((el) => { el.hidden = !hasTool(); });
  const phiField = document.querySelector("#goal-form [name=phi]");
  phiField.disabled = !wrist.enabled; // disabled: not checked, not sent
  phiField.required = wrist.enabled;
  if (hasTool()) {
    setText("tool-offset", `(${wrist.offsetM.map((v) => mm(v, 1)).join(", ")}) mm at φ = 0`);
  }
}

// Each status: the wrist's measured angle and its goal [deg].
export function renderWrist(s) {
  if (!wrist.enabled) return;
  setText("phi-meas", Number.isFinite(s.ee.phi_rad) ? `${deg(s.ee.phi_rad)}°` : "–");
  const goal = s.goal.phi_rad;
  setText("phi-goal", goal === null || goal === undefined ? "–" : `${deg(goal)}°`);
}
