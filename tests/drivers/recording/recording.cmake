# drivers/recording: the recorder, the reader and the replay source (paths relative to tests/).
stevi_test(drivers/recording/recording_test SOURCES drivers/recording/recording_test.cc
  LIBS stevi_recording stevi_drivers opencv_imgcodecs opencv_calib3d)
stevi_test(drivers/recording/replay_source_test SOURCES drivers/recording/replay_source_test.cc
  LIBS stevi_recording stevi_drivers)
