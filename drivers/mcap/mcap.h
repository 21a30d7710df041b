// The MCAP container (https://mcap.dev/spec): a writer and a reader of our own, which know nothing
// of what the messages encode (protobuf, JSON): schemas and messages are bytes. The format's types
// are in mcap_format.h, the writer in mcap_writer.h, the reader in mcap_reader.h.
// drivers/mcap/README.md says how the data flows and what the limits are.
#pragma once

#include "drivers/mcap/mcap_format.h"  // IWYU pragma: export
#include "drivers/mcap/mcap_reader.h"  // IWYU pragma: export
#include "drivers/mcap/mcap_writer.h"  // IWYU pragma: export
