// stevi mcap info FILE | stevi mcap recover FILE --out FIXED: what an MCAP flight log holds, and an
// indexed copy of one cut short (a crash, a full disk), which Foxglove then opens at once.
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <string>

#include "client/cli/commands.h"
#include "core/common/flags.h"
#include "drivers/mcap/mcap.h"

namespace stevi::client::commands {
namespace {

int Fail(const std::string& message) {
  std::cerr << "stevi: mcap: " << message << "\n";
  return 1;
}

// Opens FILE and reads every message: a file cut short is read to its last whole chunk.
struct Loaded {
  std::unique_ptr<mcap::Reader> reader;
  std::vector<mcap::Message> messages;
};

Result<Loaded> Load(const std::string& path) {
  Result<std::unique_ptr<mcap::Reader>> reader = mcap::Reader::Open(path);
  if (!reader.ok()) return reader.error();
  Loaded out{std::move(reader).value(), {}};
  Result<std::vector<mcap::Message>> all = out.reader->ReadAll();
  if (!all.ok()) return all.error();
  out.messages = std::move(all).value();
  return out;
}

int Info(const std::string& path) {
  Result<Loaded> loaded = Load(path);
  if (!loaded.ok()) return Fail(loaded.error().message);
  const mcap::Reader& r = *loaded->reader;
  std::map<uint16_t, uint64_t> counts;
  uint64_t first = 0, last = 0;
  for (const mcap::Message& m : loaded->messages) {
    ++counts[m.channel_id];
    if (first == 0 || m.log_time_ns < first) first = m.log_time_ns;
    last = std::max(last, m.log_time_ns);
  }
  const double span_s = static_cast<double>(last - first) / 1e9;
  std::cout << path << ": " << r.file_size() << " bytes, written by '" << r.header().library
            << "', " << (r.indexed() ? "indexed" : "NOT indexed") << "\n"
            << "  " << loaded->messages.size() << " messages over " << std::fixed
            << std::setprecision(1) << span_s << " s\n";
  for (const auto& [id, channel] : r.channels()) {
    const mcap::Schema* schema = r.schema(channel.schema_id);
    const uint64_t n = counts.count(id) ? counts.at(id) : 0;
    std::cout << "  " << std::left << std::setw(26) << channel.topic << std::right << std::setw(8)
              << n << "  " << (span_s > 0 && n > 1 ? static_cast<double>(n - 1) / span_s : 0.0)
              << " Hz  " << (schema ? schema->name : std::string("(no schema)")) << "\n";
  }
  for (const mcap::Metadata& m : r.metadata()) {
    for (const auto& [key, value] : m.values) {
      std::cout << "  " << m.name << "." << key << ": " << value << "\n";
    }
  }
  for (const mcap::Attachment& a : r.attachments()) {
    std::cout << "  attachment " << a.name << " (" << a.media_type << ", " << a.data.size()
              << " bytes)\n";
  }
  if (!r.note().empty()) {
    std::cout << "  " << r.note() << "\n"
              << "  `stevi mcap recover " << path << " --out FIXED` writes an indexed copy\n";
  }
  return 0;
}

int Recover(const std::string& path, const std::string& out_path) {
  Result<Loaded> loaded = Load(path);
  if (!loaded.ok()) return Fail(loaded.error().message);
  const mcap::Reader& r = *loaded->reader;
  mcap::WriterOptions options;
  options.profile = r.header().profile;
  Result<std::unique_ptr<mcap::Writer>> created = mcap::Writer::Create(out_path, options);
  if (!created.ok()) return Fail(created.error().message);
  mcap::Writer& w = **created;
  std::map<uint16_t, uint16_t> channel_ids;  // the file's -> the copy's
  for (const auto& [id, channel] : r.channels()) {
    uint16_t schema_id = 0;
    if (const mcap::Schema* s = r.schema(channel.schema_id)) {
      schema_id = w.AddSchema(s->name, s->encoding, s->data);
    }
    channel_ids[id] =
        w.AddChannel(schema_id, channel.topic, channel.message_encoding, channel.metadata);
  }
  for (const mcap::Metadata& m : r.metadata()) {
    if (stevi::Status s = w.AddMetadata(m.name, m.values); !s.ok()) return Fail(s.error().message);
  }
  for (const mcap::Attachment& a : r.attachments()) {
    if (stevi::Status s = w.AddAttachment(a.name, a.media_type, a.log_time_ns, a.data); !s.ok()) {
      return Fail(s.error().message);
    }
  }
  for (const mcap::Message& m : loaded->messages) {
    const auto id = channel_ids.find(m.channel_id);
    if (id == channel_ids.end()) return Fail(path + ": a message on an unknown channel");
    if (stevi::Status s = w.Write(id->second, m.log_time_ns, m.publish_time_ns, m.data); !s.ok()) {
      return Fail(s.error().message);
    }
  }
  if (stevi::Status s = w.Close(); !s.ok()) return Fail(s.error().message);
  std::cout << out_path << ": " << loaded->messages.size() << " messages on " << r.channels().size()
            << " channels, indexed\n";
  if (!r.note().empty()) std::cout << "  from " << r.note() << "\n";
  return 0;
}

}  // namespace

int Mcap(Client& /*client*/, const Args& args) {
  if (args.empty() || (args[0] != "info" && args[0] != "recover")) {
    return Usage("mcap: info FILE | recover FILE --out FIXED");
  }
  const std::string verb = args[0];
  std::string out_path;
  Args rest(args.begin() + 1, args.end());
  std::string file;
  if (!rest.empty() && rest[0].rfind("--", 0) != 0) {
    file = rest[0];
    rest.erase(rest.begin());
  }
  if (std::string problem = flags::FlagSet("mcap " + verb).Text("--out", &out_path).Parse(rest);
      !problem.empty()) {
    return Usage(problem);
  }
  if (file.empty()) return Usage("mcap " + verb + ": the MCAP file is required");
  if (verb == "info") {
    if (!out_path.empty()) return Usage("mcap info: --out is for recover");
    return Info(file);
  }
  if (out_path.empty()) return Usage("mcap recover: --out FIXED is required");
  return Recover(file, out_path);
}

const CommandSpec kMcapCommand = {"mcap", "what an MCAP flight log holds, or recover one cut short",
                                  R"(usage: stevi mcap info FILE
       stevi mcap recover FILE --out FIXED

info: what an MCAP flight log holds: channels, counts, rates, and what was lost when it was cut
short (a crash, a full disk).
recover: an indexed copy of a file cut short, up to its last whole chunk.
)",
                                  &Mcap};

}  // namespace stevi::client::commands
