// smoothfleet dashboard: live refresh of the parts of a page marked data-live-url, the age of
// what is shown, and auto-submitting filters. No libraries: the pages work without this script,
// it only saves reloads.
"use strict";

function describeAge(seconds) {
  if (seconds < 600) return Math.round(seconds) + " s";
  if (seconds < 7200) return Math.round(seconds / 60) + " min";
  return Math.round(seconds / 3600) + " h";
}

function startLiveRefresh(container, state) {
  const url = container.dataset.liveUrl;
  const period = Math.max(1, Number(container.dataset.refreshS || "5")) * 1000;
  let problem = "";
  function showAge() {
    if (!state) return;
    const stamp = container.querySelector("[data-generated-at]");
    const shown = stamp ? Date.parse(stamp.dataset.generatedAt) : NaN;
    const age = Number.isNaN(shown) ? "" : "shown data is " + describeAge(Math.max(0, (Date.now() - shown) / 1000)) + " old · ";
    state.textContent = age + (problem || "live: refreshed every " + period / 1000 + " s");
    state.classList.toggle("lost", problem !== "");
  }
  async function refresh() {
    try {
      const response = await fetch(url, { headers: { "X-Requested-With": "fetch" }, credentials: "same-origin" });
      if (response.status === 401) {
        window.location.assign("/login?next=" + encodeURIComponent(window.location.pathname + window.location.search));
        return;
      }
      if (!response.ok) throw new Error("HTTP " + response.status);
      container.innerHTML = await response.text();
      problem = "";
    } catch (error) {
      problem = "connection lost (" + error.message + "), retrying";
    } finally {
      showAge();
      window.setTimeout(refresh, period);
    }
  }
  showAge();
  window.setInterval(showAge, 1000);
  window.setTimeout(refresh, period);
}

document.addEventListener("DOMContentLoaded", () => {
  for (const live of document.querySelectorAll("[data-live-url]")) {
    const state = live.nextElementSibling && live.nextElementSibling.classList.contains("live-state") ? live.nextElementSibling : null;
    startLiveRefresh(live, state);
  }
  for (const form of document.querySelectorAll("form[data-autosubmit]")) {
    for (const select of form.querySelectorAll("select")) {
      select.addEventListener("change", () => form.submit());
    }
  }
});
