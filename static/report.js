// l3mvn report: inlined into the page by l3mvn_studio.report_page. The page reads fully without it;
// it adds sorting by a table's column and a failures / successes filter over the videos.
(function () {
  "use strict";

  function cellValue(row, index) {
    const cell = row.cells[index];
    const raw = cell.getAttribute("data-value");
    const text = raw !== null ? raw : cell.textContent.trim();
    const number = parseFloat(text);
    return Number.isNaN(number) ? text.toLowerCase() : number;
  }

  function sortBy(table, header, index) {
    const body = table.tBodies[0];
    const ascending = header.getAttribute("aria-sort") !== "ascending";
    table.querySelectorAll("th").forEach((th) => th.removeAttribute("aria-sort"));
    header.setAttribute("aria-sort", ascending ? "ascending" : "descending");
    const rows = Array.from(body.rows);
    rows.sort((a, b) => {
      const x = cellValue(a, index);
      const y = cellValue(b, index);
      const order = x < y ? -1 : x > y ? 1 : 0;
      return ascending ? order : -order;
    });
    rows.forEach((row) => body.appendChild(row));
  }

  document.querySelectorAll("table.sortable").forEach((table) => {
    const headers = table.tHead ? table.tHead.rows[table.tHead.rows.length - 1].cells : [];
    Array.from(headers).forEach((th, index) => {
      th.classList.add("sortable");
      th.tabIndex = 0;
      th.title = "sort by this column";
      th.addEventListener("click", () => sortBy(table, th, index));
      th.addEventListener("keydown", (event) => {
        if (event.key === "Enter" || event.key === " ") {
          event.preventDefault();
          sortBy(table, th, index);
        }
      });
    });
  });

  document.querySelectorAll(".filters").forEach((bar) => {
    const grid = document.getElementById(bar.getAttribute("data-for"));
    bar.querySelectorAll("button").forEach((button) => {
      button.addEventListener("click", () => {
        const show = button.getAttribute("data-show");
        bar.querySelectorAll("button").forEach((b) => b.setAttribute("aria-pressed", String(b === button)));
        grid.querySelectorAll("figure").forEach((figure) => {
          figure.hidden = show !== "all" && figure.getAttribute("data-outcome") !== show;
        });
      });
    });
  });
})();
