// The browser preview of radiosity-server (docs/service/preview.md): lists the
// caller's jobs (GET /api/jobs) and shows one converging, fed by its WatchJob stream relayed as
// Server-Sent Events (GET /api/jobs/ID/events, server/preview_http.h). Read with fetch() rather
// than EventSource, so that the bearer token travels in the Authorization header.
//
// The mesh is drawn with WebGL, one quad per element (its four announced corners; for an
// agglomerated element, one per face it holds, from member_corners), each side
// coloured by its radiosity: linear values times the exposure, then the sRGB transfer function;
// or, in false colour, the radiosity luminance (Y of the RGB radiosity, W per square scene unit)
// placed on viridis between min and max, as `radiosity render --false-color` does. A side that
// does not exist (the back of a one-sided surface) is not drawn, so a closed room is seen from
// outside through its near walls.
//
// window.radiosityPreview.state is the page's own account of what it shows (read by
// tests/browser/preview_test.py).
'use strict';
(function () {
  const $ = (id) => document.getElementById(id);
  const state = {
    token: '',
    jobs: [],
    job: '',             // The job shown (its id).
    connected: false,
    ended: null,         // {code, message} once the stream ended.
    lastError: '',
    jobState: '',
    phase: '',
    meshVersion: 0,      // Of the mesh drawn.
    meshElements: 0,
    drawnArea: 0,        // Of the quads drawn (square scene units).
    meshesReceived: 0,
    snapshots: 0,        // Complete snapshots received (with or without values).
    snapshotsApplied: 0, // Snapshots whose values are drawn.
    sequence: 0,         // Of the last complete snapshot.
    appliedSequence: 0,  // Of the values drawn.
    final: false,
    unshotFraction: NaN,
    errorEstimate: NaN,
    colorSum: 0,         // Sum of the drawn sides' radiosity (all channels), for tests.
    exposureScale: 1,
    view: { yaw: 0, pitch: 0, distance: 0 },  // The orbit camera's.
    frames: 0,
    history: [],         // [{t, unshot, error}] for the convergence plot.
  };

  // ---------------------------------------------------------------- token and jobs list
  function readHash() {
    const params = new URLSearchParams(location.hash.slice(1));
    if (params.has('token')) {
      sessionStorage.setItem('radiosity-token', params.get('token'));
      params.delete('token');
      history.replaceState(null, '', '#' + params.toString());
    }
    state.token = sessionStorage.getItem('radiosity-token') || '';
    return params.get('job') || '';
  }
  function headers() {
    return state.token ? { Authorization: 'Bearer ' + state.token } : {};
  }
  function setStatus(text) {
    $('status').textContent = text;
  }
  async function errorText(res) {
    try {
      const body = await res.json();
      if (body && body.error) return body.error.code + ': ' + body.error.message;
    } catch (e) { /* not JSON */ }
    return 'HTTP ' + res.status;
  }

  let listTimer = 0;
  async function refreshJobs() {
    clearTimeout(listTimer);
    try {
      const res = await fetch('/api/jobs', { headers: headers(), cache: 'no-store' });
      if (!res.ok) {
        state.lastError = await errorText(res);
        setStatus(res.status === 401 ? 'This server needs a token: ' + state.lastError
                                     : state.lastError);
      } else {
        const body = await res.json();
        state.jobs = body.jobs || [];
        if (!state.job) setStatus('');
        drawJobs();
      }
    } catch (e) {
      setStatus('cannot reach the server: ' + e.message);
    }
    listTimer = setTimeout(refreshJobs, 2000);
  }
  function drawJobs() {
    const body = $('jobs').tBodies[0];
    body.textContent = '';
    const jobs = state.jobs.slice().sort((a, b) => b.create_time - a.create_time);
    $('jobs-empty').hidden = jobs.length > 0;
    for (const job of jobs) {
      const row = body.insertRow();
      row.dataset.job = job.id;
      if (job.id === state.job) row.className = 'selected';
      const p = job.progress || {};
      const progress = job.state === 'RUNNING'
          ? (p.phase === 'solving' ? 'unshot ' + fmt(p.unshot_fraction)
                                   : p.phase + ' ' + Math.round(100 * (p.phase_fraction || 0)) + '%')
          : (job.stop_reason || '');
      for (const text of [job.id, job.state.toLowerCase(), job.scene.replace(/^scenes\//, ''),
                          progress]) {
        row.insertCell().textContent = text;
      }
      row.addEventListener('click', () => select(job.id));
    }
  }
  function fmt(x) {
    if (!(typeof x === 'number') || !isFinite(x)) return '-';
    if (x === 0) return '0';
    const a = Math.abs(x);
    return a >= 1e4 || a < 1e-3 ? x.toExponential(2) : x.toPrecision(3);
  }

  // ---------------------------------------------------------------- the event stream
  let abort = null;
  let generation = 0;
  let pendingMesh = null;
  let pendingSnapshot = null;
  let mesh = null;      // {version, elements, origin, corners, normal, area, memberCount}
  let values = null;    // Float32Array, 6 per element (full layout), of the drawn snapshot.
  let backExists = null;  // Uint8Array per element.

  function select(id) {
    if (abort) abort.abort();
    generation += 1;
    state.job = id;
    state.ended = null;
    state.connected = false;
    state.snapshots = state.snapshotsApplied = state.meshesReceived = 0;
    state.sequence = state.appliedSequence = state.meshVersion = state.meshElements = 0;
    state.history = [];
    state.final = false;
    state.colorSum = 0;
    mesh = values = backExists = pendingMesh = pendingSnapshot = null;
    const params = new URLSearchParams(location.hash.slice(1));
    params.set('job', id);
    history.replaceState(null, '', '#' + params.toString());
    $('title').textContent = 'jobs/' + id;
    drawJobs();
    renderer.clear();
    drawPlot();
    if (id) watch(id, generation, 0);
  }

  async function watch(id, gen, after) {
    abort = new AbortController();
    let res;
    try {
      res = await fetch('/api/jobs/' + encodeURIComponent(id) + '/events' +
                            (after > 0 ? '?after_sequence=' + after : ''),
                        { headers: headers(), cache: 'no-store', signal: abort.signal });
    } catch (e) {
      if (gen === generation) retry(id, gen, 'cannot reach the server: ' + e.message);
      return;
    }
    if (!res.ok) {
      state.lastError = await errorText(res);
      setStatus(state.lastError);
      if (res.status === 503 && gen === generation) setTimeout(() => {
        if (gen === generation) watch(id, gen, state.sequence);
      }, 2000);
      return;
    }
    state.connected = true;
    setStatus('');
    const reader = res.body.getReader();
    const decoder = new TextDecoder();
    let buffer = '';
    let searched = 0;
    try {
      for (;;) {
        const { value, done } = await reader.read();
        if (done || gen !== generation) break;
        buffer += decoder.decode(value, { stream: true });
        for (;;) {
          const end = buffer.indexOf('\n\n', Math.max(0, searched - 1));
          if (end < 0) {
            searched = buffer.length;
            break;
          }
          const block = buffer.slice(0, end);
          buffer = buffer.slice(end + 2);
          searched = 0;
          onBlock(block);
        }
      }
    } catch (e) {
      if (gen === generation && e.name !== 'AbortError') state.lastError = e.message;
    }
    state.connected = false;
    if (gen === generation && !state.ended) retry(id, gen, 'stream interrupted; reconnecting');
  }
  function retry(id, gen, why) {
    setStatus(why);
    setTimeout(() => {
      if (gen === generation && !state.ended) watch(id, gen, state.sequence);
    }, 2000);
  }

  function onBlock(block) {
    let event = 'message';
    let data = '';
    for (const line of block.split('\n')) {
      if (line.startsWith(':')) continue;  // Keep-alive.
      const colon = line.indexOf(':');
      const field = colon < 0 ? line : line.slice(0, colon);
      const value = colon < 0 ? '' : line.slice(colon + 1).replace(/^ /, '');
      if (field === 'event') event = value;
      else if (field === 'data') data += (data ? '\n' : '') + value;
    }
    if (!data) return;
    const message = JSON.parse(data);
    if (event === 'mesh') onMesh(message);
    else if (event === 'snapshot') onSnapshot(message);
    else if (event === 'end') onEnd(message);
  }

  function bytesOf(base64) {
    const text = atob(base64 || '');
    const bytes = new Uint8Array(text.length);
    for (let i = 0; i < text.length; ++i) bytes[i] = text.charCodeAt(i);
    return bytes.buffer;
  }
  const floats = (b) => new Float32Array(bytesOf(b));
  const ints = (b) => new Int32Array(bytesOf(b));

  function onMesh(m) {
    if (m.chunk_index === 0) {
      const n = m.elements;
      pendingMesh = {
        version: m.version, elements: n, origin: m.origin, received: 0, count: m.chunk_count,
        corners: new Float32Array(12 * n), normal: new Float32Array(3 * n),
        area: new Float32Array(n), memberCount: new Int32Array(n),
        memberCorners: new Array(m.chunk_count),  // Per message: its member faces' corners.
      };
    }
    const p = pendingMesh;
    if (!p || p.version !== m.version) return;
    const first = m.first_element;
    p.corners.set(floats(m.corners), 12 * first);
    p.normal.set(floats(m.normal), 3 * first);
    const area = floats(m.area);
    p.area.set(area, first);
    const members = ints(m.member_count);
    if (members.length) p.memberCount.set(members, first);
    p.memberCorners[m.chunk_index] = { first, count: area.length,
                                       corners: floats(m.member_corners) };
    p.received += 1;
    if (p.received === p.count) {
      quads(p);
      mesh = p;
      pendingMesh = null;
      state.meshesReceived += 1;
      state.meshVersion = mesh.version;
      state.meshElements = mesh.elements;
      values = null;
      renderer.setMesh(mesh);
    }
  }

  // What is drawn: a quad per leaf element (its corners) and per member face of an
  // agglomerated element (member_corners), each with the element it is coloured by. An element
  // whose message carries no member corners (too many faces) is drawn as its corners.
  function quads(p) {
    const members = (chunk, e) => (chunk.corners.length > 0 ? p.memberCount[e] : 0);
    let total = 0;
    for (const chunk of p.memberCorners) {
      for (let e = chunk.first; e < chunk.first + chunk.count; ++e) {
        total += Math.max(1, members(chunk, e));
      }
    }
    p.quadCorners = new Float32Array(12 * total);
    p.quadElement = new Int32Array(total);
    let q = 0;
    for (const chunk of p.memberCorners) {
      let next = 0;  // Member face within the message.
      for (let e = chunk.first; e < chunk.first + chunk.count; ++e) {
        if (members(chunk, e) === 0) {
          p.quadCorners.set(p.corners.subarray(12 * e, 12 * e + 12), 12 * q);
          p.quadElement[q++] = e;
          continue;
        }
        for (let k = 0; k < p.memberCount[e]; ++k, ++next) {
          p.quadCorners.set(chunk.corners.subarray(12 * next, 12 * next + 12), 12 * q);
          p.quadElement[q++] = e;
        }
      }
    }
    p.quads = q;
  }

  function onSnapshot(m) {
    if (m.chunk_index === 0) {
      pendingSnapshot = {
        sequence: m.sequence, total: m.radiosity_total, existing: m.existing_sides_only,
        backRanges: m.back_ranges || [], received: 0, count: m.chunk_count,
        values: new Float32Array(m.radiosity_total),
        errors: null,
      };
    }
    const p = pendingSnapshot;
    if (!p || p.sequence !== m.sequence) return;
    if (m.radiosity) p.values.set(floats(m.radiosity), m.radiosity_offset);
    if (m.std_error) {
      if (!p.errors) p.errors = new Float32Array(p.total);
      p.errors.set(floats(m.std_error), m.radiosity_offset);
    }
    p.received += 1;
    if (p.received !== p.count) return;
    pendingSnapshot = null;
    state.snapshots += 1;
    state.sequence = m.sequence;
    state.jobState = m.state;
    state.phase = m.progress.phase;
    state.final = m.final;
    state.unshotFraction = m.progress.unshot_fraction;
    if (m.error) state.lastError = 'job failed: ' + m.error.message;
    if (p.total > 0 && mesh && m.mesh_version === mesh.version && m.elements === mesh.elements) {
      const full = expand(p.values, m.elements, p.existing, p.backRanges);
      const errors = p.errors ? expand(p.errors, m.elements, p.existing, p.backRanges) : null;
      values = full.values;
      backExists = full.back;
      state.errorEstimate = errors ? relativeErrorRms(values, errors, backExists) : NaN;
      state.snapshotsApplied += 1;
      state.appliedSequence = m.sequence;
      renderer.setValues(values, backExists);
    }
    if (m.progress.phase === 'solving' || m.final) {
      state.history.push({ t: m.progress.elapsed_seconds, unshot: m.progress.unshot_fraction,
                           error: state.errorEstimate });
      if (state.history.length > 5000) state.history.splice(0, state.history.length - 5000);
    }
    drawInfo(m);
    drawPlot();
  }

  // The existing-sides layout (each element's front, then its back where back_ranges has it)
  // into the full one (6 floats per element), and which elements have a back side.
  function expand(compact, elements, existing, ranges) {
    const back = new Uint8Array(elements);
    if (!existing) {
      back.fill(1);
      return { values: compact, back };
    }
    for (let r = 0; r + 1 < ranges.length; r += 2) back.fill(1, ranges[r], ranges[r + 1]);
    const full = new Float32Array(6 * elements);
    let k = 0;
    for (let e = 0; e < elements; ++e) {
      for (let c = 0; c < 3; ++c) full[6 * e + c] = compact[k++];
      if (back[e]) for (let c = 0; c < 3; ++c) full[6 * e + 3 + c] = compact[k++];
    }
    return { values: full, back };
  }

  const luminance = (v, i) => 0.2126 * v[i] + 0.7152 * v[i + 1] + 0.0722 * v[i + 2];

  // The area-weighted RMS of the sides' standard errors relative to their luminance, floored at
  // 1e-3 of the area mean: summary.json's std_error_rms_relative (solver/results/summary.h).
  function relativeErrorRms(v, se, back) {
    let area = 0;
    let mean = 0;
    const sides = [];
    for (let e = 0; e < mesh.elements; ++e) {
      for (let s = 0; s < 2; ++s) {
        if (s === 1 && !back[e]) continue;
        const i = 6 * e + 3 * s;
        if (isNaN(se[i] + se[i + 1] + se[i + 2])) continue;
        sides.push(i, mesh.area[e]);
        area += mesh.area[e];
        mean += mesh.area[e] * luminance(v, i);
      }
    }
    if (!(area > 0)) return NaN;
    mean /= area;
    let rel = 0;
    for (let k = 0; k < sides.length; k += 2) {
      const i = sides[k];
      const d = Math.max(luminance(v, i), 1e-3 * mean);
      const r = d > 0 ? luminance(se, i) / d : 0;
      rel += sides[k + 1] * r * r;
    }
    return Math.sqrt(rel / area);
  }

  function onEnd(m) {
    state.ended = m;
    state.connected = false;
    if (m.code !== 'OK') {
      state.lastError = m.code + ': ' + m.message;
      setStatus(state.lastError);
      // The server is going away (UNAVAILABLE): not an end; watch() reconnects when the
      // response closes, and the job resumes after a restart.
      if (m.code === 'UNAVAILABLE') state.ended = null;
    }
    refreshJobs();
  }

  function drawInfo(m) {
    const p = m.progress;
    const parts = [m.state.toLowerCase() + (p.phase && !m.final ? ' (' + p.phase + ')' : ''),
                   'snapshot ' + m.sequence, (mesh ? mesh.elements : 0) + ' elements',
                   'unshot ' + fmt(p.unshot_fraction), 'est. error ' + fmt(state.errorEstimate),
                   fmt(p.elapsed_seconds) + ' s', fmt(p.rays) + ' rays'];
    if (m.final) parts.push('final');
    $('info').textContent = parts.join(' | ');
  }

  // ---------------------------------------------------------------- WebGL
  const VERTEX = `
    attribute vec3 position;
    attribute vec3 front;
    attribute vec4 back;  // rgb, and 1 where the back side exists.
    uniform mat4 view_projection;
    varying vec3 v_front;
    varying vec4 v_back;
    void main() {
      v_front = front;
      v_back = back;
      gl_Position = view_projection * vec4(position, 1.0);
    }`;
  const FRAGMENT = `
    precision highp float;
    varying vec3 v_front;
    varying vec4 v_back;
    uniform float exposure;
    uniform float false_color;  // 1: false colour, 0: shaded.
    uniform vec2 range;         // False colour's min and max.
    uniform sampler2D scale;    // Viridis, 256 x 1.
    vec3 srgb(vec3 c) {
      c = clamp(c, 0.0, 1.0);
      return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
    }
    void main() {
      vec3 radiosity = v_front;
      if (!gl_FrontFacing) {
        if (v_back.a < 0.5) discard;
        radiosity = v_back.rgb;
      }
      if (false_color > 0.5) {
        float y = dot(radiosity, vec3(0.2126, 0.7152, 0.0722));
        float t = clamp((y - range.x) / max(range.y - range.x, 1e-30), 0.0, 1.0);
        gl_FragColor = vec4(texture2D(scale, vec2(t * 255.0 / 256.0 + 0.5 / 256.0, 0.5)).rgb,
                            1.0);
      } else {
        gl_FragColor = vec4(srgb(radiosity * exposure), 1.0);
      }
    }`;
  const VIRIDIS = [[0x44, 0x01, 0x54], [0x48, 0x28, 0x78], [0x3e, 0x4a, 0x89],
                   [0x31, 0x68, 0x8e], [0x26, 0x82, 0x8e], [0x1f, 0x9e, 0x89],
                   [0x35, 0xb7, 0x79], [0x6e, 0xce, 0x58], [0xfd, 0xe7, 0x25]];
  function viridis(t) {
    t = Math.min(1, Math.max(0, t)) * (VIRIDIS.length - 1);
    const i = Math.min(Math.floor(t), VIRIDIS.length - 2);
    const f = t - i;
    return VIRIDIS[i].map((a, k) => Math.round((1 - f) * a + f * VIRIDIS[i + 1][k]));
  }

  const renderer = (function () {
    const canvas = $('gl');
    const gl = canvas.getContext('webgl', { antialias: true, preserveDrawingBuffer: true });
    const r = { ok: !!gl, elements: 0, center: [0, 0, 0], radius: 1,
                yaw: 0.6, pitch: 0.35, distance: 3 };
    if (!gl) {
      setStatus('this browser has no WebGL: the mesh cannot be shown');
      r.clear = r.setMesh = r.setValues = r.draw = () => {};
      return r;
    }
    const wide = gl.getExtension('OES_element_index_uint');
    function shader(type, source) {
      const s = gl.createShader(type);
      gl.shaderSource(s, source);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      return s;
    }
    const program = gl.createProgram();
    gl.attachShader(program, shader(gl.VERTEX_SHADER, VERTEX));
    gl.attachShader(program, shader(gl.FRAGMENT_SHADER, FRAGMENT));
    gl.linkProgram(program);
    gl.useProgram(program);
    const at = (n) => gl.getAttribLocation(program, n);
    const un = (n) => gl.getUniformLocation(program, n);
    const attributes = { position: at('position'), front: at('front'), back: at('back') };
    const uniforms = { viewProjection: un('view_projection'), exposure: un('exposure'),
                       falseColor: un('false_color'), range: un('range'), scale: un('scale') };
    const buffers = { position: gl.createBuffer(), front: gl.createBuffer(),
                      back: gl.createBuffer(), index: gl.createBuffer() };
    const texture = gl.createTexture();
    const texels = new Uint8Array(256 * 4);
    for (let i = 0; i < 256; ++i) {
      const c = viridis(i / 255);
      texels.set([c[0], c[1], c[2], 255], 4 * i);
    }
    gl.bindTexture(gl.TEXTURE_2D, texture);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, 256, 1, 0, gl.RGBA, gl.UNSIGNED_BYTE, texels);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    gl.enable(gl.DEPTH_TEST);

    r.clear = function () {
      r.elements = 0;
      r.draw();
    };
    r.setMesh = function (m) {
      const n = m.elements;
      const nq = m.quads;
      if (4 * nq > 65536 && !wide) {
        setStatus('this browser cannot draw more than 16384 quads');
        r.elements = 0;
        return;
      }
      // Four vertices per quad: its corners (12 floats per quad, already in order).
      gl.bindBuffer(gl.ARRAY_BUFFER, buffers.position);
      gl.bufferData(gl.ARRAY_BUFFER, m.quadCorners, gl.STATIC_DRAW);
      const index = wide ? new Uint32Array(6 * nq) : new Uint16Array(6 * nq);
      for (let q = 0; q < nq; ++q) {
        index.set([4 * q, 4 * q + 1, 4 * q + 2, 4 * q, 4 * q + 2, 4 * q + 3], 6 * q);
      }
      quadElement = m.quadElement;
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.index);
      gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, index, gl.STATIC_DRAW);
      // Until values arrive: grey fronts, no backs.
      upload(new Float32Array(6 * n).fill(0.18), new Uint8Array(n));
      r.exposure = 1;
      let lo = [Infinity, Infinity, Infinity];
      let hi = [-Infinity, -Infinity, -Infinity];
      for (let i = 0; i < m.quadCorners.length; i += 3) {
        for (let k = 0; k < 3; ++k) {
          lo[k] = Math.min(lo[k], m.quadCorners[i + k]);
          hi[k] = Math.max(hi[k], m.quadCorners[i + k]);
        }
      }
      const fresh = r.elements === 0;
      r.elements = n;
      r.quads = nq;
      state.drawnArea = 0;
      for (let i = 0; i < m.quadCorners.length; i += 12) {
        const c = m.quadCorners;
        const tri = (a, b, d) => {
          const u = [0, 1, 2].map((k) => c[i + 3 * b + k] - c[i + 3 * a + k]);
          const v = [0, 1, 2].map((k) => c[i + 3 * d + k] - c[i + 3 * a + k]);
          return 0.5 * Math.hypot(...cross(u, v));
        };
        state.drawnArea += tri(0, 1, 2) + tri(0, 2, 3);
      }
      r.center = lo.map((a, k) => 0.5 * (a + hi[k]));
      r.radius = Math.max(1e-9, 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));
      if (fresh) r.resetView();
      r.draw();
    };
    let front = new Float32Array(0);
    let backs = new Float32Array(0);
    let quadElement = new Int32Array(0);
    // Each quad's four vertices get its element's front and back radiosity.
    function upload(full, back) {
      const nq = quadElement.length;
      if (front.length !== 12 * nq) {  // Reused from snapshot to snapshot of one mesh.
        front = new Float32Array(12 * nq);
        backs = new Float32Array(16 * nq);
      }
      for (let q = 0; q < nq; ++q) {
        const e = quadElement[q];
        for (let v = 0; v < 4; ++v) {
          for (let c = 0; c < 3; ++c) {
            front[12 * q + 3 * v + c] = full[6 * e + c];
            backs[16 * q + 4 * v + c] = full[6 * e + 3 + c];
          }
          backs[16 * q + 4 * v + 3] = back[e];
        }
      }
      gl.bindBuffer(gl.ARRAY_BUFFER, buffers.front);
      gl.bufferData(gl.ARRAY_BUFFER, front, gl.DYNAMIC_DRAW);
      gl.bindBuffer(gl.ARRAY_BUFFER, buffers.back);
      gl.bufferData(gl.ARRAY_BUFFER, backs, gl.DYNAMIC_DRAW);
    }
    r.setValues = function (full, back) {
      if (!r.elements) return;
      upload(full, back);
      // Automatic exposure: the area-weighted geometric mean of the drawn sides' luminance
      // (floored at 1e-4 of the arithmetic mean, so that unlit sides count but do not rule)
      // maps to 0.5, the slider's 0 EV. Emitters, however large, then saturate rather than
      // darken everything else.
      let area = 0;
      let sum = 0;
      let total = 0;
      for (let e = 0; e < r.elements; ++e) {
        for (let s = 0; s < 2; ++s) {
          if (s === 1 && !back[e]) continue;
          const i = 6 * e + 3 * s;
          area += mesh.area[e];
          sum += mesh.area[e] * luminance(full, i);
          total += full[i] + full[i + 1] + full[i + 2];
        }
      }
      const floor = area > 0 ? 1e-4 * sum / area : 0;
      let logs = 0;
      if (floor > 0) {
        for (let e = 0; e < r.elements; ++e) {
          logs += mesh.area[e] * Math.log(Math.max(floor, luminance(full, 6 * e)));
          if (back[e]) logs += mesh.area[e] * Math.log(Math.max(floor, luminance(full, 6 * e + 3)));
        }
      }
      r.mean = floor > 0 ? Math.exp(logs / area) : 0;
      r.max = 0;
      for (let e = 0; e < r.elements; ++e) {
        r.max = Math.max(r.max, luminance(full, 6 * e), back[e] ? luminance(full, 6 * e + 3) : 0);
      }
      state.colorSum = total;
      r.draw();
    };
    // The first view looks from the side where the most front area faces the eye (into an open
    // box through its opening): of eight directions around the mesh, 20 degrees up.
    function bestYaw(m) {
      let best = 0.6;
      let bestScore = -1;
      for (let k = 0; k < 8; ++k) {
        const yaw = 0.6 + k * Math.PI / 4;
        const d = [Math.cos(0.35) * Math.sin(yaw), Math.sin(0.35), Math.cos(0.35) * Math.cos(yaw)];
        let score = 0;
        for (let e = 0; e < m.elements; ++e) {
          const c = m.normal[3 * e] * d[0] + m.normal[3 * e + 1] * d[1] + m.normal[3 * e + 2] * d[2];
          if (c > 0) score += m.area[e] * c;
        }
        if (score > bestScore + 1e-9 * Math.abs(bestScore)) {
          best = yaw;
          bestScore = score;
        }
      }
      return best;
    }
    r.resetView = function () {
      r.yaw = mesh ? bestYaw(mesh) : 0.6;
      r.pitch = 0.35;
      r.distance = r.radius / Math.sin(0.5 * FOV) * 1.05;
      r.draw();
    };
    const FOV = 45 * Math.PI / 180;
    r.draw = function () {
      state.frames += 1;
      state.view = { yaw: r.yaw, pitch: r.pitch, distance: r.distance };
      gl.viewport(0, 0, canvas.width, canvas.height);
      gl.clearColor(0.07, 0.07, 0.07, 1);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      if (!r.elements) return;
      const ev = Number($('exposure').value);
      const exposure = (r.mean > 0 ? 0.5 / r.mean : 1) * Math.pow(2, ev);
      state.exposureScale = exposure;
      const fc = falseColorRange();
      gl.uniform1f(uniforms.exposure, exposure);
      gl.uniform1f(uniforms.falseColor, fc ? 1 : 0);
      gl.uniform2f(uniforms.range, fc ? fc[0] : 0, fc ? fc[1] : 1);
      gl.uniform1i(uniforms.scale, 0);
      gl.uniformMatrix4fv(uniforms.viewProjection, false, viewProjection());
      const bind = (buffer, location, size) => {
        gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
        gl.enableVertexAttribArray(location);
        gl.vertexAttribPointer(location, size, gl.FLOAT, false, 0, 0);
      };
      bind(buffers.position, attributes.position, 3);
      bind(buffers.front, attributes.front, 3);
      bind(buffers.back, attributes.back, 4);
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.index);
      gl.drawElements(gl.TRIANGLES, 6 * r.quads, wide ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT, 0);
      drawLegend(fc);
    };
    function viewProjection() {
      const cp = Math.cos(r.pitch);
      const eye = [r.center[0] + r.distance * cp * Math.sin(r.yaw),
                   r.center[1] + r.distance * Math.sin(r.pitch),
                   r.center[2] + r.distance * cp * Math.cos(r.yaw)];
      const f = normalize(r.center.map((c, k) => c - eye[k]));
      const s = normalize(cross(f, [0, 1, 0]));
      const u = cross(s, f);
      const near = Math.max(1e-4 * r.radius, r.distance - 2 * r.radius);
      const far = r.distance + 2 * r.radius;
      const t = 1 / Math.tan(0.5 * FOV);
      const aspect = canvas.width / canvas.height;
      // Column-major: projection x view.
      const view = [s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0,
                    -dot(s, eye), -dot(u, eye), dot(f, eye), 1];
      const proj = [t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1,
                    0, 0, 2 * far * near / (near - far), 0];
      const out = new Float32Array(16);
      for (let c = 0; c < 4; ++c) {
        for (let row = 0; row < 4; ++row) {
          let x = 0;
          for (let k = 0; k < 4; ++k) x += proj[4 * k + row] * view[4 * c + k];
          out[4 * c + row] = x;
        }
      }
      return out;
    }
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                             a[0] * b[1] - a[1] * b[0]];
    const normalize = (a) => {
      const l = Math.hypot(a[0], a[1], a[2]) || 1;
      return a.map((x) => x / l);
    };

    // Orbit: drag to turn around the mesh's centre, wheel to come closer.
    let drag = null;
    canvas.addEventListener('pointerdown', (e) => {
      drag = { x: e.clientX, y: e.clientY };
      canvas.setPointerCapture(e.pointerId);
      canvas.classList.add('dragging');
    });
    canvas.addEventListener('pointermove', (e) => {
      if (!drag) return;
      r.yaw -= 0.01 * (e.clientX - drag.x);
      r.pitch = Math.max(-1.5, Math.min(1.5, r.pitch + 0.01 * (e.clientY - drag.y)));
      drag = { x: e.clientX, y: e.clientY };
      r.draw();
    });
    const stop = () => {
      drag = null;
      canvas.classList.remove('dragging');
    };
    canvas.addEventListener('pointerup', stop);
    canvas.addEventListener('pointercancel', stop);
    canvas.addEventListener('wheel', (e) => {
      e.preventDefault();
      r.distance = Math.max(1e-3 * r.radius, r.distance * Math.exp(0.001 * e.deltaY));
      r.draw();
    }, { passive: false });
    return r;
  })();

  // ---------------------------------------------------------------- false colour and legend
  // [min, max] of the false-colour scale, or null when it is off: the inputs, else 0 and the
  // largest luminance drawn.
  function falseColorRange() {
    if (!$('false-color').checked) return null;
    const min = $('fc-min').value === '' ? 0 : Number($('fc-min').value);
    const max = $('fc-max').value === '' ? (renderer.max || 1) : Number($('fc-max').value);
    return isFinite(min) && isFinite(max) && max > min ? [min, max] : [0, renderer.max || 1];
  }
  function drawLegend(range) {
    const canvas = $('legend');
    canvas.hidden = !range;
    if (!range) return;
    const g = canvas.getContext('2d');
    const top = 10;
    const height = canvas.height - 20;
    g.clearRect(0, 0, canvas.width, canvas.height);
    for (let y = 0; y < height; ++y) {
      const c = viridis(1 - y / (height - 1));
      g.fillStyle = 'rgb(' + c.join(',') + ')';
      g.fillRect(6, top + y, 18, 1);
    }
    g.fillStyle = '#222';
    g.font = '11px sans-serif';
    for (let k = 0; k <= 4; ++k) {
      const y = top + (1 - k / 4) * (height - 1);
      g.fillText(fmt(range[0] + (range[1] - range[0]) * k / 4), 28, y + 4);
    }
    g.save();
    g.translate(canvas.width - 4, top + height / 2);
    g.rotate(-Math.PI / 2);
    g.textAlign = 'center';
    g.fillText('W/m\u00b2 (luminance)', 0, 0);
    g.restore();
  }

  // ---------------------------------------------------------------- convergence plot
  function drawPlot() {
    const canvas = $('plot');
    const g = canvas.getContext('2d');
    const W = canvas.width;
    const H = canvas.height;
    const left = 56;
    const right = 12;
    const top = 12;
    const bottom = 34;
    g.clearRect(0, 0, W, H);
    g.strokeStyle = '#444';
    g.strokeRect(left, top, W - left - right, H - top - bottom);
    g.fillStyle = '#222';
    g.font = '11px sans-serif';
    const h = state.history;
    const positive = h.flatMap((p) => [p.unshot, p.error]).filter((x) => x > 0 && isFinite(x));
    const lo = Math.floor(Math.log10(positive.length ? Math.min(...positive) : 1e-3));
    const hi = Math.max(lo + 1, Math.ceil(Math.log10(positive.length ? Math.max(...positive) : 1)));
    const tMax = Math.max(1e-3, ...h.map((p) => p.t));
    const x = (t) => left + (W - left - right) * t / tMax;
    const y = (v) => top + (H - top - bottom) * (hi - Math.log10(v)) / (hi - lo);
    for (let e = lo; e <= hi; ++e) {
      g.fillText('1e' + e, 8, y(Math.pow(10, e)) + 4);
    }
    for (let k = 0; k <= 4; ++k) g.fillText(fmt(tMax * k / 4), x(tMax * k / 4) - 8, H - 18);
    g.fillText('seconds of solving', W / 2 - 40, H - 4);
    const series = (key, color, dash) => {
      g.strokeStyle = color;
      g.setLineDash(dash);
      g.lineWidth = 2;
      g.beginPath();
      let started = false;
      for (const p of h) {
        const v = p[key];
        if (!(v > 0 && isFinite(v))) continue;
        if (started) g.lineTo(x(p.t), y(v));
        else g.moveTo(x(p.t), y(v));
        started = true;
      }
      g.stroke();
      g.setLineDash([]);
      return started;
    };
    series('unshot', '#26828e', []);
    g.fillStyle = '#26828e';
    g.fillText('unshot fraction', left + 10, top + 14);
    if (series('error', '#b5651d', [2, 3])) {
      g.fillStyle = '#b5651d';
      g.fillText('estimated relative error (RMS standard error)', left + 10, top + 28);
    }
  }

  // ---------------------------------------------------------------- controls
  $('exposure').addEventListener('input', () => {
    $('exposure-value').textContent = $('exposure').value + ' EV';
    renderer.draw();
  });
  for (const id of ['false-color', 'fc-min', 'fc-max']) {
    $(id).addEventListener('input', () => renderer.draw());
  }
  $('reset-view').addEventListener('click', () => renderer.resetView());
  $('token-form').addEventListener('submit', (e) => {
    e.preventDefault();
    state.token = $('token').value.trim();
    sessionStorage.setItem('radiosity-token', state.token);
    $('token').value = '';
    refreshJobs();
    if (state.job) select(state.job);
  });
  window.addEventListener('hashchange', () => {
    const job = readHash();
    if (job && job !== state.job) select(job);
  });

  window.radiosityPreview = {
    state,
    // The drawn radiosity of element e's side (0 front, 1 back), [r, g, b]; null when none.
    radiosity(e, side) {
      if (!values || e < 0 || e >= values.length / 6) return null;
      return Array.from(values.subarray(6 * e + 3 * side, 6 * e + 3 * side + 3));
    },
    select,
  };

  const job = readHash();
  refreshJobs();
  drawPlot();
  if (job) select(job);
})();
