# The station's Foxglove WebSocket server against the protocol's specification, over loopback
# (tests/testing/ws_client.h), and the test client's own RFC 6455 checks.
stevi_test(client/station/foxglove_server_test SOURCES client/station/foxglove_server_test.cc
  LIBS stevi_foxglove_server stevi_foxglove_convert stevi_testing_ws stevi_proto nlohmann_json::nlohmann_json
  Threads::Threads TIMEOUT 120)

# The ground station's page in headless Chromium against a real stevi-server and `stevi station`.
stevi_test(client/station/station_browser_test SOURCES client/station/station_browser_test.cc
  LIBS stevi_client stevi_calibration stevi_testing_process stevi_testing_browser Threads::Threads
  TIMEOUT 300)
add_dependencies(client_station_station_browser_test stevi-server stevi)

# The station in process against a real stevi-server: its channels, previews on demand, the
# access token, the API; and the `stevi station` command's refusals.
stevi_test(client/station/station_test SOURCES client/station/station_test.cc
  LIBS stevi_station stevi_testing_process stevi_testing_ws opencv_imgcodecs Threads::Threads
  TIMEOUT 300)
add_dependencies(client_station_station_test stevi-server stevi)
