# Command-line flags: the flag library's FlagSet and number parser, and the servers' command line
# made from the settings' field lists.
stevi_fuzz(flags SOURCES ${CMAKE_CURRENT_LIST_DIR}/flags_fuzz.cc
  LIBS stevi_flags stevi_server_lib)
