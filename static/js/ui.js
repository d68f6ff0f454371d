// Small page helpers: text updates without layout churn, and a transient message line.

let toastTimer = null;

export function setText(id, text) {
  const el = document.getElementById(id);
  if (el && el.textContent !== text) el.textContent = text;
}

export function showMessage(text, kind = "info") {
  const toast = document.getElementById("toast");
  toast.textContent = text;
  toast.className = `toast ${kind}`;
  toast.hidden = false;
  clearTimeout(toastTimer);
  toastTimer = setTimeout(() => { toast.hidden = true; }, kind === "error" ? 8000 : 3000);
}

export function showError(err) {
  const status = err && err.status ? ` (${err.status})` : "";
  showMessage(`${err && err.message ? err.message : err}${status}`, "error");
}
