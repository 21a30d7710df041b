# Aravis cameras (drivers/aravis): the pairing logic alone, then the camera and the source
# against Aravis's in-process fake camera and against two real arv-fake-gv-camera-0.8
# processes. Included from tests/CMakeLists.txt; paths are relative to tests/.
if(TARGET stevi_aravis)
  stevi_test(drivers/aravis/stereo_pairer_test SOURCES drivers/aravis/stereo_pairer_test.cc
    LIBS stevi_pairing LABELS aravis TIMEOUT 60)

  # The fake GigE Vision camera of Debian's aravis-tools. When it is missing the GigE tests fail
  # and say so (they never skip silently).
  find_program(STEVI_ARV_FAKE_GV_CAMERA arv-fake-gv-camera-0.8)

  # One executable, two ctest entries: the in-process fake interface needs no network; the GigE
  # tests run in a private network namespace (fake_camera_netns.sh) where the cameras get
  # 127.0.0.1 and 127.0.0.2 and port 3956 clashes with nothing.
  # The fake camera as a child process of a test (also used by tests/server/aravis_test).
  add_library(stevi_testing_fake_camera STATIC testing/fake_gv_camera.cc)
  target_include_directories(stevi_testing_fake_camera PUBLIC ${PROJECT_SOURCE_DIR})
  target_compile_definitions(stevi_testing_fake_camera PRIVATE
    STEVI_ARV_FAKE_GV_CAMERA="${STEVI_ARV_FAKE_GV_CAMERA}")
  target_link_libraries(stevi_testing_fake_camera PUBLIC GTest::gtest stevi_aravis
    PRIVATE stevi_warnings)
  add_executable(drivers_aravis_aravis_source_test drivers/aravis/aravis_source_test.cc)
  target_link_libraries(drivers_aravis_aravis_source_test PRIVATE stevi_testing GTest::gtest_main
    stevi_aravis stevi_testing_fake_camera opencv_imgproc stevi_warnings)
  add_test(NAME drivers/aravis/aravis_camera_test
    COMMAND drivers_aravis_aravis_source_test --gtest_filter=-AravisGigE*)
  add_test(NAME drivers/aravis/aravis_source_test
    COMMAND /bin/sh ${CMAKE_CURRENT_SOURCE_DIR}/drivers/fake_camera_netns.sh
            $<TARGET_FILE:drivers_aravis_aravis_source_test> --gtest_filter=AravisGigE*)
  set_tests_properties(drivers/aravis/aravis_camera_test PROPERTIES LABELS aravis TIMEOUT 120)
  # RESOURCE_LOCK: where no private namespace can be made, the fake cameras share the host's
  # GigE Vision port (see fake_camera_netns.sh).
  set_tests_properties(drivers/aravis/aravis_source_test PROPERTIES LABELS aravis TIMEOUT 300
    RESOURCE_LOCK fake_gige_cameras)
endif()
