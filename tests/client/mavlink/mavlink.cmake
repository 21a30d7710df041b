# MAVLink: the codec against frames worked out by hand from the specification, random and mutated
# frames, the messages' layouts and field tables, and the links over loopback UDP and a
# pseudo-terminal.
stevi_test(client/mavlink/codec_test SOURCES client/mavlink/codec_test.cc LIBS stevi_mavlink_codec)
stevi_test(client/mavlink/messages_test SOURCES client/mavlink/messages_test.cc LIBS stevi_mavlink_codec)
stevi_test(client/mavlink/field_table_test SOURCES client/mavlink/field_table_test.cc LIBS stevi_mavlink_codec)
stevi_test(client/mavlink/fuzz_test SOURCES client/mavlink/fuzz_test.cc LIBS stevi_mavlink_codec)
stevi_test(client/mavlink/link_test SOURCES client/mavlink/link_test.cc LIBS stevi_mavlink_link Threads::Threads)
stevi_test(client/mavlink/translate_test SOURCES client/mavlink/translate_test.cc LIBS stevi_mavlink_translate)
