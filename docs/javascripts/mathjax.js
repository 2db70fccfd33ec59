// MathJax 3 for the pages' math (pymdownx.arithmatex) and the notebooks' markdown cells.
// On a page, only what arithmatex marks is typeset (as the Material theme recommends);
// on a notebook page, also $...$ and $$...$$ in the text (code and outputs are <pre>/<code>,
// which MathJax skips).
(function () {
  const notebook = document.querySelector(".jupyter-wrapper") !== null;
  window.MathJax = {
    tex: {
      inlineMath: notebook ? [["\\(", "\\)"], ["$", "$"]] : [["\\(", "\\)"]],
      displayMath: notebook ? [["\\[", "\\]"], ["$$", "$$"]] : [["\\[", "\\]"]],
      processEscapes: true,
      processEnvironments: true,
    },
    options: notebook ? {} : { ignoreHtmlClass: ".*|", processHtmlClass: "arithmatex" },
  };
})();
