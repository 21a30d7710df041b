# drivers/mcap: the MCAP writer and reader (paths relative to tests/). The tests check the bytes
# with libzstd, LZ4F and zlib directly, independently of the library.
pkg_check_modules(STEVI_MCAP_TEST_ZSTD REQUIRED IMPORTED_TARGET libzstd)
pkg_check_modules(STEVI_MCAP_TEST_LZ4 REQUIRED IMPORTED_TARGET liblz4)
find_package(ZLIB REQUIRED)
stevi_test(drivers/mcap/format_test SOURCES drivers/mcap/format_test.cc
  LIBS stevi_mcap PkgConfig::STEVI_MCAP_TEST_ZSTD PkgConfig::STEVI_MCAP_TEST_LZ4 ZLIB::ZLIB)
stevi_test(drivers/mcap/round_trip_test SOURCES drivers/mcap/round_trip_test.cc LIBS stevi_mcap)
stevi_test(drivers/mcap/recovery_test SOURCES drivers/mcap/recovery_test.cc LIBS stevi_mcap)
