# Command-line flags: the stevi tool's FlagSet and number parser, the servers' ParseFlags and
# ApplyFlags.
stevi_fuzz(flags SOURCES ${CMAKE_CURRENT_LIST_DIR}/flags_fuzz.cc
  LIBS stevi_client_logic stevi_server_lib)
