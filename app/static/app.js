// The page of `mesh2tex app`: uploads, jobs, their progress, and the result in <model-viewer>.
// Every request of this tab carries its own session (asked for on load), so tabs never share files.
const $ = (id) => document.getElementById(id);
const state = { session: null, info: null, job: null, polling: null, pressed: 0 };
// what the tests and the timing script read: when Generate or Transfer was pressed and when the viewer showed the GLB
window.mesh2tex = { pressed: 0, done: 0, loaded: 0, seconds: 0, glb: "", ready: false, jobSeconds: 0 };

async function call(method, path, body, headers) {
  const response = await fetch(path, { method, body, headers });
  let data = null;
  try { data = await response.json(); } catch (e) { data = null; }
  if (!response.ok) {
    const line = data && data.error ? data.error : `mesh2tex: error: the server answered ${response.status}`;
    throw new Error(line);
  }
  return data;
}
const api = (path) => `/api/s/${state.session}${path}`;

function showError(line) {
  $("error").textContent = line || "";
  $("error").hidden = !line;
}

function fill(select, options) {
  select.replaceChildren(...options.map(([value, text]) => new Option(text, value)));
}

async function upload(role, file) {
  showError("");
  const summary = $(`${role}-summary`);
  const limit = state.info.limits_mb[role];
  if (file.size > limit * 1048576) {  // the server refuses it too, without keeping a byte
    summary.textContent = "";
    const size = (file.size / 1048576).toFixed(1);
    showError(`mesh2tex: error: ${file.name}: ${size} MB is over the upload limit of ${limit.toFixed(1)} MB`);
    return;
  }
  summary.textContent = `uploading ${file.name} ...`;
  try {
    const data = await call("POST", api(`/upload/${role}?name=${encodeURIComponent(file.name)}`), file);
    summary.textContent = data.summary;
    if (role === "mesh") showPreview(data.name);
  } catch (error) {
    summary.textContent = "";
    showError(error.message);
  }
}

async function useExample(role, name) {
  if (!name) return;
  showError("");
  try {
    const data = await call("POST", api(`/example/${role}/${encodeURIComponent(name)}`));
    $(`${role}-summary`).textContent = `${data.summary} (example)`;
    if (role === "mesh") showPreview(data.name);
  } catch (error) {
    showError(error.message);
  }
}

// the mesh as uploaded, untextured: the viewer shows it (and is ready for the result) before any job,
// and again while a job runs (the previous job's files are gone by then)
function showPreview(name) {
  for (const id of ["gallery", "pictures"]) $(id).replaceChildren();
  $("pose").textContent = "";
  $("download").hidden = true;
  if (name) state.meshName = name;
  $("viewer").src = api(`/preview?upload=${Date.now()}`);
  $("result-label").textContent = `${state.meshName}, untextured`;
}

function dropZone(zone, input, role) {
  input.addEventListener("change", () => { if (input.files.length) upload(role, input.files[0]); input.value = ""; });
  zone.addEventListener("dragover", (event) => { event.preventDefault(); zone.classList.add("over"); });
  zone.addEventListener("dragleave", () => zone.classList.remove("over"));
  zone.addEventListener("drop", (event) => {
    event.preventDefault();
    zone.classList.remove("over");
    if (event.dataTransfer.files.length) upload(role, event.dataTransfer.files[0]);
  });
}

function sourceChanged() {
  const source = $("source").value;
  const shipped = state.info.models.includes(source);
  $("nca-box").hidden = source !== "nca";
  $("exemplar-box").hidden = source !== "exemplar";
  $("count-box").hidden = !shipped;
  $("quick-box").hidden = source === "nca";
  $("transfer").disabled = !shipped || running();
  $("transfer").title = shipped ? "" : "a transfer needs a shipped model";
}

function setSeed(value) {
  const seed = Math.max(0, Math.floor(Number(value) || 0));
  $("seed").value = seed;
  $("seed-slider").value = Math.min(seed, 999);
}

const running = () => state.job !== null && ["queued", "running"].includes(state.job.status);

function setBusy(busy) {
  $("generate").disabled = busy;
  $("transfer").disabled = busy || !state.info.models.includes($("source").value);
  $("cancel").hidden = !busy;
  $("job").hidden = false;
  $("viewer").autoRotate = !busy;  // a turning model keeps a GPU-less machine's browser busy while the job runs
}

async function start(kind) {
  showError("");
  const request = { kind, source: $("source").value, seed: Number($("seed").value), count: Number($("count").value),
                    quick: $("quick").checked };
  window.mesh2tex.pressed = performance.now();
  window.mesh2tex.loaded = 0;
  try {
    state.job = await call("POST", api("/jobs"), JSON.stringify(request), { "Content-Type": "application/json" });
  } catch (error) {
    showError(error.message);
    return;
  }
  setBusy(true);
  showPreview();
  showJob(state.job);
  clearInterval(state.polling);
  state.polling = setInterval(poll, 250);
}

async function poll() {
  const id = state.job.id;
  let job;
  try {
    job = await call("GET", api(`/jobs/${id}`));
  } catch (error) {
    clearInterval(state.polling);
    setBusy(false);
    showError(error.message);
    return;
  }
  if (!state.job || state.job.id !== id) return;
  state.job = job;
  showJob(job);
  if (!running()) {
    clearInterval(state.polling);
    setBusy(false);
    window.mesh2tex.jobSeconds = job.seconds;  // the command's own wall time, from its start to its end
    window.mesh2tex.done = performance.now();  // when the page learnt that the job had ended
    if (job.status === "done") showResults(job);
    else showError(job.status === "cancelled" ? "cancelled: nothing was kept" : job.error);
  }
}

function showJob(job) {
  const what = job.status === "queued" ? "waiting for another job to finish" : job.stage || job.status;
  $("stage").textContent = `${job.label}: ${what}` + (job.total ? ` (${job.done}/${job.total})` : "") +
    (job.status === "done" ? ` - done in ${job.seconds} s` : "");
  $("bar").value = job.status === "done" ? 1 : job.total ? job.done / job.total : 0;
  $("log").textContent = job.log.join("\n");
}

function fileUrl(job, name) {
  return api(`/jobs/${job.id}/files/${encodeURIComponent(name)}`);
}

function showMesh(job, entry) {
  window.mesh2tex.glb = entry.glb;
  $("viewer").src = fileUrl(job, entry.glb);
  $("download").href = fileUrl(job, entry.glb) + "?download=1";
  $("download").hidden = false;
  $("result-label").textContent = `${job.label}: ${entry.label}` + (job.kept ? ` (kept as ${job.kept})` : "");
  for (const button of $("gallery").children) button.classList.toggle("chosen", button.dataset.glb === entry.glb);
}

function showResults(job) {
  const found = job.results;
  $("gallery").replaceChildren(...(found.meshes.length > 1 ? found.meshes : []).map((entry) => {
    const button = document.createElement("button");
    button.dataset.glb = entry.glb;
    if (entry.thumb) {
      const image = document.createElement("img");
      image.src = fileUrl(job, entry.thumb);
      image.alt = entry.label;
      button.append(image);
    }
    const caption = document.createElement("span");
    caption.textContent = entry.label;
    button.append(caption);
    button.addEventListener("click", () => showMesh(job, entry));
    return button;
  }));
  $("pictures").replaceChildren(...found.pictures.map((picture) => {
    const figure = document.createElement("figure");
    const image = document.createElement("img");
    image.src = fileUrl(job, picture.file);
    image.alt = picture.caption;
    const caption = document.createElement("figcaption");
    caption.textContent = picture.caption;
    figure.append(image, caption);
    return figure;
  }));
  const pose = found.pose;
  $("pose").textContent = pose ? `estimated pose: azimuth ${pose.azimuth}°, elevation ${pose.elevation}° ` +
    `(${pose.source}); silhouette IoU ${found.fit.silhouette_iou}, low-pass PSNR ${found.fit.lowpass_psnr} dB` +
    (found.fit.poor ? `; a poor fit: ${found.fit.problems.join("; ")}` : "") : "";
  if (found.meshes.length) showMesh(job, found.meshes[0]);
}

async function main() {
  state.info = await call("GET", "/api/info");
  state.session = (await call("POST", "/api/session")).session;
  $("where").textContent = state.info.local ? `served on this machine only (mesh2tex ${state.info.version})` :
    `shared on the network: anyone who can reach this machine can use this page (mesh2tex ${state.info.version})`;
  fill($("source"), [...state.info.models.map((m) => [m, `shipped model: ${m}`]), ["nca", "an NCA model (upload)"],
                     ["exemplar", "an exemplar image (upload)"]]);
  fill($("count"), [1, 2, 4, 8, 16].filter((n) => n <= state.info.max_seeds).map((n) => [n, String(n)]));
  fill($("mesh-example"), [["", "-"], ...state.info.examples.mesh.map((n) => [n, n])]);
  fill($("photo-example"), [["", "-"], ...state.info.examples.photo.map((n) => [n, n])]);
  for (const role of ["mesh", "photo", "nca", "exemplar"]) {
    const input = $(`${role}-file`);
    if (role === "mesh") input.accept = state.info.suffixes.mesh.join(",");
    if ($(`${role}-drop`)) dropZone($(`${role}-drop`), input, role);
    else input.addEventListener("change", () => { if (input.files.length) upload(role, input.files[0]); });
  }
  $("mesh-example").addEventListener("change", () => useExample("mesh", $("mesh-example").value));
  $("photo-example").addEventListener("change", () => useExample("photo", $("photo-example").value));
  $("source").addEventListener("change", sourceChanged);
  $("seed-slider").addEventListener("input", () => setSeed($("seed-slider").value));
  $("seed").addEventListener("change", () => setSeed($("seed").value));
  $("random").addEventListener("click", () => setSeed(Math.floor(Math.random() * 1000)));
  $("generate").addEventListener("click", () => start("generate"));
  $("transfer").addEventListener("click", () => start("transfer"));
  $("cancel").addEventListener("click", () => {
    call("POST", api(`/jobs/${state.job.id}/cancel`)).catch((e) => showError(e.message));
  });
  $("viewer").addEventListener("load", () => {
    const timing = window.mesh2tex;
    // timed once per job, at the first result it shows (not a preview of the mesh)
    if (!timing.pressed || timing.loaded || !$("viewer").src.includes("/jobs/")) return;
    timing.loaded = performance.now();
    timing.seconds = (timing.loaded - timing.pressed) / 1000;
    $("result-label").textContent += ` - in the viewer ${timing.seconds.toFixed(1)} s after pressing`;
  });
  $("viewer").addEventListener("error", () => showError("mesh2tex: error: the viewer could not show the GLB"));
  window.addEventListener("pagehide", () => navigator.sendBeacon(api("/close")));
  setInterval(() => call("GET", api("/alive")).catch((e) => showError(e.message)), 60000);
  sourceChanged();
  window.mesh2tex.ready = true;
}

main().catch((error) => showError(error.message));
