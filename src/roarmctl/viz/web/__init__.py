"""The browser view of a plan or a run: one self-contained HTML page (``page``) that ``visualize-path -o
x.html`` writes and ``roarmctl view`` serves on 127.0.0.1 (``server``), from the numbers of ``document``.

Everything the page shows is computed here in Python with the library's FK, Jacobian and FCL geometry and
embedded per sample; the page's own script (``static/view.js``) only places what it is given. The 3D
library is three.js from the pinned ``jupyter-threejs-sage`` package, inlined when the page is written.
"""
