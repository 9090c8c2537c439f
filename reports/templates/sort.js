// Sortable tables (no library, no network): click (or Enter on) a header with data-col to sort every
// tbody of its table by that column; again to reverse. A cell's data-sort, else its text, is the key;
// numbers sort as numbers, empty keys last in both directions; a tbody's first row of class "group"
// (a family's heading) stays on top.
(function () {
  "use strict";
  function key(cell) {
    if (!cell) { return null; }
    var s = cell.hasAttribute("data-sort") ? cell.getAttribute("data-sort") : cell.textContent.trim();
    if (s === "" || s === "–" || s === "-") { return null; }
    var n = Number(s);
    return isNaN(n) ? s.toLowerCase() : n;
  }
  function compare(a, b, dir) {
    if (a === null || b === null) { return (a === null) - (b === null); }
    if (typeof a !== typeof b) { return dir * (typeof a === "number" ? -1 : 1); }
    return dir * (a < b ? -1 : a > b ? 1 : 0);
  }
  function sortBy(th) {
    var table = th.closest("table");
    var col = Number(th.getAttribute("data-col"));
    var dir = th.getAttribute("aria-sort") === "ascending" ? -1 : 1;
    table.querySelectorAll("th[aria-sort]").forEach(function (o) { o.removeAttribute("aria-sort"); });
    th.setAttribute("aria-sort", dir === 1 ? "ascending" : "descending");
    Array.prototype.forEach.call(table.tBodies, function (tb) {
      var rows = Array.prototype.filter.call(tb.rows, function (r) { return !r.classList.contains("group"); });
      var keyed = rows.map(function (r, i) { return {r: r, k: key(r.cells[col]), i: i}; });
      keyed.sort(function (a, b) { return compare(a.k, b.k, dir) || a.i - b.i; });
      keyed.forEach(function (x) { tb.appendChild(x.r); });
    });
  }
  document.querySelectorAll("table.sortable th[data-col]").forEach(function (th) {
    th.tabIndex = 0;
    th.classList.add("sorter");
    th.addEventListener("click", function (ev) { if (!ev.target.closest("a")) { sortBy(th); } });
    th.addEventListener("keydown", function (ev) {
      if (ev.key === "Enter" || ev.key === " ") { ev.preventDefault(); sortBy(th); }
    });
  });
})();
