# The MAVLink link's bytes: frame parser, message decoders, the bridge's PoseJoiner.
stevi_fuzz(mavlink SOURCES ${CMAKE_CURRENT_LIST_DIR}/mavlink_fuzz.cc LIBS stevi_mavlink_translate)
