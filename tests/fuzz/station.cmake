# The ground station's untrusted inputs: the page's HTTP requests (through the station's routing
# into its API) and the Foxglove WebSocket clients' frames and messages.
stevi_fuzz(station_http SOURCES ${CMAKE_CURRENT_LIST_DIR}/station_http_fuzz.cc
  LIBS stevi_station civetweb::civetweb nlohmann_json::nlohmann_json)
stevi_fuzz(foxglove_ws SOURCES ${CMAKE_CURRENT_LIST_DIR}/foxglove_ws_fuzz.cc
  LIBS stevi_foxglove_server nlohmann_json::nlohmann_json)
