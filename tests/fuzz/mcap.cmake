# The MCAP reader (drivers/mcap): footer, summary, linear recovery, chunk decompression, messages.
stevi_fuzz(mcap SOURCES ${CMAKE_CURRENT_LIST_DIR}/mcap_fuzz.cc LIBS stevi_mcap)
