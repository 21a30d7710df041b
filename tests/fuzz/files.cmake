# The file and configuration parsers: config files (text format and JSON), the calibration store's
# YAML (calibrations and reports), uploaded calibration images, and recordings.
stevi_fuzz(config SOURCES ${CMAKE_CURRENT_LIST_DIR}/config_fuzz.cc LIBS stevi_server_lib)
stevi_fuzz(calibration_yaml SOURCES ${CMAKE_CURRENT_LIST_DIR}/calibration_yaml_fuzz.cc
           LIBS stevi_calibration stevi_geometry)
stevi_fuzz(calibration_image SOURCES ${CMAKE_CURRENT_LIST_DIR}/calibration_image_fuzz.cc
           LIBS stevi_calibration)
stevi_fuzz(recording SOURCES ${CMAKE_CURRENT_LIST_DIR}/recording_fuzz.cc
           LIBS stevi_recording stevi_flight_export stevi_mcap)
