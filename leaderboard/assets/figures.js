// brdfbench report: the cells' figures. Lobe panels switch between log and linear radius and
// show or hide an incident inclination; a render or error map opens enlarged on a click (or
// Enter) and closes on Escape or a click. No dependencies, no network.
(function () {
  "use strict";
  document.querySelectorAll("[data-lobes]").forEach(function (figure) {
    figure.querySelectorAll("input[data-lobe-scale]").forEach(function (radio) {
      radio.addEventListener("change", function () {
        if (radio.checked) figure.classList.toggle("lobe-linear", radio.value === "linear");
      });
    });
    figure.querySelectorAll("input[data-lobe-ti]").forEach(function (box) {
      box.addEventListener("change", function () {
        var j = box.getAttribute("data-lobe-ti");
        figure.querySelectorAll('[data-ti="' + j + '"]').forEach(function (el) {
          el.style.display = box.checked ? "" : "none";
        });
      });
    });
  });

  var overlay = null;
  var opener = null;
  function close() {
    if (!overlay) return;
    overlay.remove();
    overlay = null;
    if (opener) opener.focus();
  }
  function open(img) {
    close();
    opener = img;
    overlay = document.createElement("div");
    overlay.className = "lightbox";
    overlay.setAttribute("role", "dialog");
    overlay.setAttribute("aria-label", img.alt);
    var big = document.createElement("img");
    big.src = img.src;
    big.alt = img.alt;
    var caption = document.createElement("p");
    var cell = img.closest("figure");
    var note = cell ? cell.querySelector("figcaption") : null;
    caption.textContent = img.alt + (note && note.textContent ? " · " + note.textContent : "") +
      "  (Escape or click to close)";
    overlay.appendChild(big);
    overlay.appendChild(caption);
    overlay.addEventListener("click", close);
    document.body.appendChild(overlay);
  }
  document.querySelectorAll("img[data-enlarge]").forEach(function (img) {
    img.addEventListener("click", function () { open(img); });
    img.addEventListener("keydown", function (e) {
      if (e.key === "Enter" || e.key === " ") { e.preventDefault(); open(img); }
    });
  });
  document.addEventListener("keydown", function (e) {
    if (e.key === "Escape") close();
  });
})();
