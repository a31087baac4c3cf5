// smoothfleet dashboard: live refresh of the fleet table and auto-submitting filters.
// No libraries: the page works without this script, it only saves reloads.
"use strict";

function startLiveRefresh(container) {
  const url = container.dataset.liveUrl;
  const period = Math.max(1, Number(container.dataset.refreshS || "5")) * 1000;
  const state = document.getElementById("live-state");
  async function refresh() {
    try {
      const response = await fetch(url, { headers: { "X-Requested-With": "fetch" }, credentials: "same-origin" });
      if (response.status === 401) {
        window.location.assign("/login?next=" + encodeURIComponent(window.location.pathname + window.location.search));
        return;
      }
      if (!response.ok) throw new Error("HTTP " + response.status);
      container.innerHTML = await response.text();
      if (state) { state.textContent = "live: refreshed every " + period / 1000 + " s"; state.classList.remove("lost"); }
    } catch (error) {
      if (state) { state.textContent = "connection lost (" + error.message + "), retrying"; state.classList.add("lost"); }
    } finally {
      window.setTimeout(refresh, period);
    }
  }
  window.setTimeout(refresh, period);
}

document.addEventListener("DOMContentLoaded", () => {
  const live = document.getElementById("fleet-live");
  if (live) startLiveRefresh(live);
  for (const form of document.querySelectorAll("form[data-autosubmit]")) {
    for (const select of form.querySelectorAll("select")) {
      select.addEventListener("change", () => form.submit());
    }
  }
});
