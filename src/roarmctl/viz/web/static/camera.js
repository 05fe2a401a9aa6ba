// roarmctl's browser view, its camera (inlined into the page before view.js, as view.js is): a perspective and an
// orthographic camera under OrbitControls, the PNG's named views, and the wheel's zoom toward the cursor.
// ``window.roarmCamera(THREE, canvas, VIEWS, centre, span, changed)``: VIEWS maps a view's name to [elevation,
// azimuth] in degrees; centre (Vector3) and span (m) frame the scene; changed(viewName) is called after every change
// (view.js draws then). Returns { camera (the one in use), controls, setView, setOrthographic, isOrthographic,
// zoomAt, setAspect }.
(function () {
  'use strict';
  window.roarmCamera = function (THREE, canvas, VIEWS, centre, span, changed) {
    // Two cameras, one in use (the "orthographic" toggle): perspective, and orthographic for measuring by eye.
    const perspective = new THREE.PerspectiveCamera(35, 1, 0.002, 100);
    const orthographic = new THREE.OrthographicCamera(-1, 1, 1, -1, -100, 100);
    perspective.up.set(0, 0, 1);
    orthographic.up.set(0, 0, 1);
    let camera = perspective;
    const controls = new THREE.OrbitControls(camera, canvas);
    controls.enableZoom = false;  // the wheel zooms toward the cursor (below), not toward the orbit's centre
    // The PNG's views (elevation, azimuth in degrees; path_figure.VIEWS): the camera looks at the scene's centre from
    // there. Straight down is nudged off the pole, where the orbit's "up" would be undefined.
    let viewName = 'iso';
    function setView(name) {
      const [elev, azim] = VIEWS[name] || VIEWS.iso;
      viewName = VIEWS[name] ? name : 'iso';
      const e = Math.min(elev, 89.9) * Math.PI / 180, a = azim * Math.PI / 180;
      const dir = new THREE.Vector3(Math.cos(e) * Math.cos(a), Math.cos(e) * Math.sin(a), Math.sin(e));
      const dist = 0.5 * span / Math.tan(0.5 * perspective.fov * Math.PI / 180) * 0.9;
      camera.position.copy(centre).addScaledVector(dir, dist);
      controls.target.copy(centre);
      if (camera === orthographic) { orthographic.zoom = 1; fitOrthographic(dist); }
      controls.update();
      changed(viewName);
    }

    // orthographic: a frustum as tall as the perspective camera sees at the orbit's centre
    function fitOrthographic(dist) {
      const h = dist * Math.tan(0.5 * perspective.fov * Math.PI / 180), w = h * perspective.aspect;
      Object.assign(orthographic, { left: -w, right: w, top: h, bottom: -h });
      orthographic.updateProjectionMatrix();
    }
    function setOrthographic(on) {
      const next = on ? orthographic : perspective;
      if (next === camera) return;
      const dist = camera.position.distanceTo(controls.target) / (camera === orthographic ? orthographic.zoom : 1);
      next.position.copy(camera.position);
      next.quaternion.copy(camera.quaternion);
      camera = next;
      controls.object = camera;
      if (on) { orthographic.zoom = 1; fitOrthographic(dist); }
      controls.update();
      changed(viewName);
    }

    // The wheel zooms toward the point under the cursor: that point stays under it (a scaling about it in
    // perspective; in orthographic the zoom, then a shift that brings it back).
    const ray = new THREE.Raycaster(), plane = new THREE.Plane();
    function pointUnder(clientX, clientY) {
      const r = canvas.getBoundingClientRect();
      ray.setFromCamera(new THREE.Vector2((clientX - r.left) / r.width * 2 - 1, 1 - (clientY - r.top) / r.height * 2), camera);
      plane.setFromNormalAndCoplanarPoint(camera.getWorldDirection(new THREE.Vector3()), controls.target);
      return ray.ray.intersectPlane(plane, new THREE.Vector3());
    }
    function zoomAt(clientX, clientY, factor) {  // factor < 1: closer
      const p = pointUnder(clientX, clientY);
      if (!p) return;
      if (camera === perspective) {
        const d = camera.position.distanceTo(controls.target) * factor;
        if (d < 0.01 || d > 50 * span) return;
        camera.position.sub(p).multiplyScalar(factor).add(p);
        controls.target.sub(p).multiplyScalar(factor).add(p);
      } else {
        orthographic.zoom = Math.min(Math.max(orthographic.zoom / factor, 0.02), 500);
        orthographic.updateProjectionMatrix();
        const q = pointUnder(clientX, clientY);
        if (q) { const shift = p.sub(q); camera.position.add(shift); controls.target.add(shift); }
      }
      controls.update();
      changed(viewName);
    }
    canvas.addEventListener('wheel', (ev) => {
      ev.preventDefault();
      zoomAt(ev.clientX, ev.clientY, Math.exp(Math.max(-1, Math.min(1, ev.deltaY * 0.002))));
    }, { passive: false });

    function setAspect(aspect) {  // the canvas's width / height
      perspective.aspect = aspect;
      perspective.updateProjectionMatrix();
      if (camera === orthographic) fitOrthographic(orthographic.top / Math.tan(0.5 * perspective.fov * Math.PI / 180));
    }

    return {
      get camera() { return camera; },
      controls: controls,
      setView: setView,
      setOrthographic: setOrthographic,
      isOrthographic: () => camera === orthographic,
      zoomAt: zoomAt,
      setAspect: setAspect,
    };
  };
})();
