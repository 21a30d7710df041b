// The stevi station page: one panel per rig, fed by the station's Foxglove WebSocket channels
// (/rigK/tracks, /rigK/status, /rigK/image/annotated, /rigK/image/disparity, /rigK/vehicle) and
// its HTTP API (/api/...). ES modules, no build step, nothing from the internet; this entry wires
// them together (README.md lists what each module holds).
//
// Everything received (messages, JSON, error texts) is untrusted: it reaches the page through
// textContent and attribute values only, never innerHTML.
//
// DOM hooks (for tests): #socket-state[data-state=open|closed|connecting]; #station-token-form
// (#station-token, #station-token-apply); #operator-token; #problems[data-count]; per rig
// section.rig[data-rig=rigK] with span.rig-state[data-state=up|down|connecting], .rig-address,
// .rig-error, .source-state, img.video[data-kind=annotated|disparity][data-seq][data-stamp],
// canvas.plan, div.map[data-geo=ok|none] + .map-message, a.export-geojson, a.export-kml,
// table.tracks[data-frame-id] > tbody > tr[data-track-id][data-state] > td.range[data-range-m],
// div.status [data-key], details.controls (select.algorithm, button.apply-algorithm,
// [data-field=dotted.path] inputs, span.field-error[data-field], button.apply-config,
// div.config-error, .control-result, select.snapshot-kind, button.snapshot, div.calibrations
// with button.activate-calibration[data-id]); the snapshot shows in .snapshot-overlay.
//
// window.stevi exposes the state for tests (state.js):
//   {rigs: {rig1: {name, address, lastFrame, lastStatus, lastVehicle, frames, decodeErrors,
//                  images: {annotated: n, disparity: n}, config}},
//    socketOpen, problems: [{key, message, count, time}], subscribed: [topics], serverInfo}

import { Proto } from './util.js';
import './state.js';
import { addProblem, renderProblems } from './problems.js';
import { initTokenForms } from './api.js';
import { refreshRigs } from './rigs.js';
import { connect, reconnectNow } from './socket.js';
import { closeSnapshotOnEscape } from './snapshot.js';

initTokenForms(() => {
  refreshRigs();
  reconnectNow();
});
closeSnapshotOnEscape();

if (!Proto) {
  addProblem('protobuf', 'protobuf.js did not load: nothing can be decoded');
}
renderProblems();
refreshRigs();
connect();
