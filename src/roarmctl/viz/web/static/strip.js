// roarmctl's browser view, its clearance strip (inlined into the page before view.js): every scene item's distance
// over the samples in its colour (intended contact in its own), the padding dashed, the smallest clearance that is not
// intended contact marked. ``window.roarmStrip(canvas, o)``: o.n samples, o.m items, o.clearance (n * m, m; -1 not
// measured), o.intended (n * m, 0/1), o.padding (m or null), o.minimum {index, item, distance}, o.names, o.color(k),
// o.intendedColor, o.tightColor. Draws at the canvas's CSS size times the device pixel ratio.
(function () {
  'use strict';
  // The clearance strip under the timeline: every item's distance over time (its colour; intended contact green),
  // the padding dashed, the smallest clearance that is not intended contact marked. Drawn once per size, not per frame.
  window.roarmStrip = function (strip, o) {
    const N = o.n, M = o.m, ICLEAR = o.clearance, INTENDED = o.intended, PAD = o.padding, MINIMUM = o.minimum;
    const ratio = window.devicePixelRatio || 1;
    const w = strip.clientWidth, h = strip.clientHeight;
    strip.width = Math.max(1, Math.round(w * ratio));
    strip.height = Math.max(1, Math.round(h * ratio));
    const g = strip.getContext('2d');
    g.setTransform(ratio, 0, 0, ratio, 0, 0);
    g.fillStyle = '#fafbfc';
    g.fillRect(0, 0, w, h);
    const top = Math.min(0.1, Math.max(0.02, PAD ? 4 * PAD : 0, MINIMUM.index >= 0 ? 2 * MINIMUM.distance : 0));
    const x = (i) => (N > 1 ? i / (N - 1) : 0) * w, y = (d) => h - 2 - Math.min(d / top, 1) * (h - 12);
    for (let k = 0; k < M; k++) {
      for (let i = 0; i + 1 < N; i++) {
        const a = ICLEAR[i * M + k], b = ICLEAR[(i + 1) * M + k];
        if (a < 0 || b < 0) continue;
        g.strokeStyle = INTENDED[i * M + k] && INTENDED[(i + 1) * M + k] ? o.intendedColor : o.color(k);
        g.lineWidth = INTENDED[i * M + k] ? 2.5 : 1.3;
        g.beginPath(); g.moveTo(x(i), y(a)); g.lineTo(x(i + 1), y(b)); g.stroke();
      }
    }
    g.font = '10px system-ui, sans-serif';
    if (PAD) {
      g.strokeStyle = o.tightColor; g.lineWidth = 1; g.setLineDash([4, 3]);
      g.beginPath(); g.moveTo(0, y(PAD)); g.lineTo(w, y(PAD)); g.stroke(); g.setLineDash([]);
      g.fillStyle = o.tightColor; g.fillText('padding ' + (PAD * 1000).toFixed(1) + ' mm', 3, y(PAD) - 2);
    }
    g.fillStyle = '#555';
    g.fillText((top * 1000).toFixed(0) + ' mm', w - 40, 10);
    if (MINIMUM.index >= 0) {
      const mx = x(MINIMUM.index), my = y(MINIMUM.distance);
      g.fillStyle = o.tightColor;
      g.beginPath(); g.arc(mx, my, 4, 0, 2 * Math.PI); g.fill();
      const text = 'min ' + (MINIMUM.distance * 1000).toFixed(1) + ' mm: ' + o.names[MINIMUM.item];
      g.fillText(text, Math.min(mx + 6, w - g.measureText(text).width - 2), Math.max(my - 4, 20));
    }
  };
})();
