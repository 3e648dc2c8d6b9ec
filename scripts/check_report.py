#!/usr/bin/env python3
"""The checker behind check_report.sh.

`inject REPORT OUT`: writes a copy of REPORT with a <base> pointing at REPORT's directory
and a script that, once the page and its images have loaded, records in the DOM
(`<pre id="report-check">`, JSON) every image's naturalWidth and every element wider than the
viewport or reaching past its right edge.

`verdict DOM`: reads the dumped DOM, prints one line per problem and exits 1 if there is any.
"""

import html
import json
import pathlib
import re
import sys

CHECK_JS = r"""
<script>
window.addEventListener('load', () => {
  const vw = document.documentElement.clientWidth;
  const images = [...document.images].map(img => ({
    src: img.getAttribute('src'),
    naturalWidth: img.naturalWidth,
    naturalHeight: img.naturalHeight,
    shownWidth: Math.round(img.getBoundingClientRect().width),
  }));
  const overflow = [];
  for (const el of document.body.querySelectorAll('*')) {
    const r = el.getBoundingClientRect();
    // Scrolling boxes (overflow: auto) may be wider inside; their own box must fit.
    // An element whose content spills out of its box (overflow: visible) also counts.
    const spills = el.scrollWidth > el.clientWidth + 1 && el.clientWidth > 0 &&
      getComputedStyle(el).overflowX === 'visible' && r.left + el.scrollWidth > vw + 0.5;
    if (r.right > vw + 0.5 || r.left < -0.5 || spills) {
      overflow.push({tag: el.tagName.toLowerCase(), text: (el.textContent || '').slice(0, 60),
                     left: Math.round(r.left),
                     right: Math.round(Math.max(r.right, r.left + el.scrollWidth))});
    }
  }
  const out = document.createElement('pre');
  out.id = 'report-check';
  out.textContent = JSON.stringify({
    viewportWidth: vw,
    scrollWidth: document.documentElement.scrollWidth,
    images, overflow,
  });
  document.body.appendChild(out);
});
</script>
"""


def inject(report: str, out: str) -> None:
    src = pathlib.Path(report)
    text = src.read_text(encoding="utf-8")
    base = f'<base href="{src.parent.resolve().as_uri()}/">'
    if "<head>" in text:
        text = text.replace("<head>", "<head>" + base, 1)
    else:
        text = base + text
    text = text.replace("</body>", CHECK_JS + "</body>", 1) if "</body>" in text else text + CHECK_JS
    pathlib.Path(out).write_text(text, encoding="utf-8")


def verdict(dom: str) -> int:
    text = pathlib.Path(dom).read_text(encoding="utf-8", errors="replace")
    m = re.search(r'<pre id="report-check">(.*?)</pre>', text, re.S)
    if not m:
        print("FAIL: the checker did not run (no report-check element in the dumped DOM)")
        return 1
    r = json.loads(html.unescape(m.group(1)))
    problems = []
    if not r["images"]:
        problems.append("no <img> on the page")
    for img in r["images"]:
        state = "ok" if img["naturalWidth"] > 0 else "NOT LOADED"
        print(f"img {img['src']}: {img['naturalWidth']}x{img['naturalHeight']} px, "
              f"shown {img['shownWidth']} px wide: {state}")
        if img["naturalWidth"] <= 0:
            problems.append(f"image {img['src']} did not load")
    if r["scrollWidth"] > r["viewportWidth"]:
        problems.append(f"page scrolls sideways: {r['scrollWidth']} px > {r['viewportWidth']} px")
    for o in r["overflow"]:
        problems.append(f"<{o['tag']}> spans x = {o['left']}..{o['right']} px beyond the "
                        f"{r['viewportWidth']} px page: {o['text']!r}")
    for p in problems:
        print("FAIL:", p)
    if not problems:
        print(f"ok: {len(r['images'])} images loaded, nothing wider than {r['viewportWidth']} px")
    return 1 if problems else 0


def main() -> int:
    if len(sys.argv) == 4 and sys.argv[1] == "inject":
        inject(sys.argv[2], sys.argv[3])
        return 0
    if len(sys.argv) == 3 and sys.argv[1] == "verdict":
        return verdict(sys.argv[2])
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
