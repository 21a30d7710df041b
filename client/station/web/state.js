// The page's state, exposed as window.stevi for the tests:
//   {rigs: {rig1: {name, address, lastFrame, lastStatus, lastVehicle, frames, decodeErrors,
//                  images: {annotated: n, disparity: n}, config}},
//    socketOpen, problems: [{key, message, count, time}], subscribed: [topics], serverInfo}
// rigs.rigK is each Rig's `pub` (rig.js); the socket (socket.js) keeps the rest.

export const stevi = {
  rigs: {},
  socketOpen: false,
  problems: [],
  subscribed: [],
  serverInfo: null,
};
window.stevi = stevi;
