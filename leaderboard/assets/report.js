// brdfbench report: sortable tables and series toggles; no dependencies, no network.
(function () {
  "use strict";
  function sortKey(cell) {
    var raw = cell.getAttribute("data-sort");
    if (raw === null) raw = cell.textContent.trim();
    if (raw === "" || raw === "–") return null;
    var num = Number(raw);
    return isNaN(num) ? raw.toLowerCase() : num;
  }
  function sortTable(table, th, column) {
    var ascending = th.getAttribute("aria-sort") !== "ascending";
    Array.prototype.forEach.call(table.tHead.rows[0].cells, function (h) { h.removeAttribute("aria-sort"); });
    th.setAttribute("aria-sort", ascending ? "ascending" : "descending");
    // every row group but the reference one (the target itself stays above the ranking)
    Array.prototype.forEach.call(table.tBodies, function (body) {
      if (!body.classList.contains("reference")) sortBody(body, column, ascending);
    });
  }
  function sortBody(body, column, ascending) {
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {
      var x = sortKey(a.cells[column]), y = sortKey(b.cells[column]);
      if (x === null && y === null) return 0;
      if (x === null) return 1;  // a missing figure sorts last either way
      if (y === null) return -1;
      var order = (typeof x === "number" && typeof y === "number") ? x - y : String(x).localeCompare(String(y));
      return ascending ? order : -order;
    });
    rows.forEach(function (r) { body.appendChild(r); });
  }
  document.querySelectorAll("table.sortable").forEach(function (table) {
    Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, column) {
      th.tabIndex = 0;
      th.addEventListener("click", function () { sortTable(table, th, column); });
      th.addEventListener("keydown", function (e) {
        if (e.key === "Enter" || e.key === " ") { e.preventDefault(); sortTable(table, th, column); }
      });
    });
  });
  document.querySelectorAll("input[data-series]").forEach(function (box) {
    box.addEventListener("change", function () {
      var prefix = box.getAttribute("data-series");
      document.querySelectorAll('[id^="' + prefix + '"]').forEach(function (el) {
        el.style.display = box.checked ? "" : "none";
      });
    });
  });
})();
