// The station's Foxglove WebSocket server against the protocol's specification
// (foxglove/ws-protocol docs/spec.md) and RFC 6455, over loopback on an ephemeral port. Tests wait
// on messages and subscription events, each with a deadline; none sleeps to synchronise.
#include "client/station/foxglove_server.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "foxglove/CompressedImage.pb.h"
#include "foxglove/ImageAnnotations.pb.h"
#include "foxglove/LocationFix.pb.h"
#include "foxglove/SceneUpdate.pb.h"
#include "proto/foxglove/convert.h"
#include "stevi/v1/obstacle_service.pb.h"
#include "tests/testing/ws_client.h"

namespace stevi::station {
namespace {

using Json = nlohmann::json;
using stevi::testing::HttpReply;
using stevi::testing::HttpRequestOnce;
using stevi::testing::WsClient;
using stevi::testing::WsMessage;
using stevi::testing::WsOptions;
using ::testing::HasSubstr;
using to_foxglove::FileDescriptorSetFor;

constexpr std::chrono::seconds kTimeout(5);
const char kV1[] = "foxglove.websocket.v1";
const char kSdk[] = "foxglove.sdk.v1";

std::unique_ptr<FoxgloveServer> StartServer(FoxgloveServerOptions options = {}) {
  options.listen = "127.0.0.1:0";
  std::string error;
  std::unique_ptr<FoxgloveServer> server = FoxgloveServer::Start(options, error);
  if (server == nullptr) throw std::runtime_error("cannot start the server: " + error);
  return server;
}

std::unique_ptr<WsClient> Connect(const FoxgloveServer& server, WsOptions options = {}) {
  if (options.subprotocols.empty()) options.subprotocols = {kV1};
  std::string error;
  std::unique_ptr<WsClient> client = WsClient::Connect("127.0.0.1", server.port(), options, error);
  if (client == nullptr) throw std::runtime_error("cannot connect: " + error);
  return client;
}

std::optional<HttpReply> Http(const FoxgloveServer& server, const std::string& method,
                              const std::string& target,
                              const std::vector<std::pair<std::string, std::string>>& headers = {},
                              const std::string& body = "") {
  std::string error;
  std::optional<HttpReply> reply =
      HttpRequestOnce("127.0.0.1", server.port(), method, target, headers, body, error);
  EXPECT_TRUE(reply.has_value()) << method << " " << target << ": " << error;
  return reply;
}

// The next message, which must be JSON text; a null json on failure (after reporting it).
Json NextJson(WsClient& client) {
  const std::optional<WsMessage> message = client.Receive(kTimeout);
  if (!message) {
    ADD_FAILURE() << "no message within " << kTimeout.count() << " s";
    return Json();
  }
  if (message->opcode != WsMessage::kText) {
    ADD_FAILURE() << "expected a text message, got opcode " << message->opcode;
    return Json();
  }
  Json json = Json::parse(message->payload, nullptr, false);
  EXPECT_FALSE(json.is_discarded()) << message->payload;
  return json;
}

// The next message, which must be a status warning; its text.
std::string NextWarning(WsClient& client) {
  const Json status = NextJson(client);
  EXPECT_EQ(status.value("op", ""), "status") << status;
  EXPECT_EQ(status.value("level", -1), 1) << status;
  return status.value("message", "");
}

// Connects and reads serverInfo and, with channels, the advertise.
std::unique_ptr<WsClient> ConnectAndGreet(const FoxgloveServer& server, bool has_channels) {
  std::unique_ptr<WsClient> client = Connect(server);
  EXPECT_EQ(client->status(), 101);
  EXPECT_EQ(NextJson(*client).value("op", ""), "serverInfo");
  if (has_channels) {
    EXPECT_EQ(NextJson(*client).value("op", ""), "advertise");
  }
  return client;
}

void Subscribe(WsClient& client, const std::vector<std::pair<uint32_t, uint32_t>>& id_channel) {
  Json subscriptions = Json::array();
  for (const auto& [id, channel] : id_channel) {
    subscriptions.push_back({{"id", id}, {"channelId", channel}});
  }
  ASSERT_TRUE(client.SendText(Json{{"op", "subscribe"}, {"subscriptions", subscriptions}}.dump()));
}

void Unsubscribe(WsClient& client, const std::vector<uint32_t>& ids) {
  ASSERT_TRUE(client.SendText(Json{{"op", "unsubscribe"}, {"subscriptionIds", ids}}.dump()));
}

// A Message Data frame, taken apart.
struct DataFrame {
  uint32_t subscription = 0;
  uint64_t log_time_ns = 0;
  std::string payload;
};

// The next message, which must be a Message Data frame.
std::optional<DataFrame> NextData(WsClient& client) {
  const std::optional<WsMessage> message = client.Receive(kTimeout);
  if (!message) {
    ADD_FAILURE() << "no message within " << kTimeout.count() << " s";
    return std::nullopt;
  }
  if (message->opcode != WsMessage::kBinary || message->payload.size() < 13 ||
      message->payload[0] != 0x01) {
    ADD_FAILURE() << "expected a Message Data frame, got opcode " << message->opcode << ": "
                  << message->payload.substr(0, 200);
    return std::nullopt;
  }
  DataFrame frame;
  for (int i = 3; i >= 0; --i) {
    frame.subscription = (frame.subscription << 8) | uint8_t(message->payload[1 + i]);
  }
  for (int i = 7; i >= 0; --i) {
    frame.log_time_ns = (frame.log_time_ns << 8) | uint8_t(message->payload[5 + i]);
  }
  frame.payload = message->payload.substr(13);
  return frame;
}

// The subscription listener's calls, waited for in order.
class SubscriptionLog {
 public:
  std::function<void(uint32_t, bool)> Listener() {
    return [this](uint32_t channel, bool subscribed) {
      std::lock_guard lock(mutex_);
      events_.emplace_back(channel, subscribed);
      cv_.notify_all();
    };
  }
  // Waits for the next event; true if it is (channel, subscribed).
  ::testing::AssertionResult Next(uint32_t channel, bool subscribed) {
    std::unique_lock lock(mutex_);
    if (!cv_.wait_for(lock, kTimeout, [&] { return next_ < events_.size(); })) {
      return ::testing::AssertionFailure() << "no listener call for channel " << channel;
    }
    const auto event = events_[next_++];
    if (event != std::make_pair(channel, subscribed)) {
      return ::testing::AssertionFailure()
             << "listener got (" << event.first << ", " << event.second << "), expected ("
             << channel << ", " << subscribed << ")";
    }
    return ::testing::AssertionSuccess();
  }
  size_t size() {
    std::lock_guard lock(mutex_);
    return events_.size();
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<std::pair<uint32_t, bool>> events_;
  size_t next_ = 0;
};

// A server whose subscription listener reports to `log`, which must outlive it (Stop() calls the
// listener).
std::unique_ptr<FoxgloveServer> StartServer(SubscriptionLog& log,
                                            FoxgloveServerOptions options = {}) {
  std::unique_ptr<FoxgloveServer> server = StartServer(std::move(options));
  server->SetSubscriptionListener(log.Listener());
  return server;
}

// Polls `condition` until it holds or the deadline passes (for server state that sends nothing,
// such as a freed client slot).
bool Eventually(const std::function<bool()>& condition) {
  const auto deadline = std::chrono::steady_clock::now() + kTimeout;
  while (!condition()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

ChannelSpec Spec(const std::string& topic, const google::protobuf::Descriptor* descriptor,
                 bool lossy = false) {
  ChannelSpec spec;
  spec.topic = topic;
  spec.schema_name = descriptor->full_name();
  spec.schema = FileDescriptorSetFor(descriptor);
  spec.lossy = lossy;
  return spec;
}

foxglove::CompressedImage SomeImage() {
  foxglove::CompressedImage image;
  image.mutable_timestamp()->set_seconds(1700000000);
  image.mutable_timestamp()->set_nanos(123);
  image.set_data(std::string("\xff\xd8\xff\xe0 not really a jpeg", 22));
  image.set_format("jpeg");
  image.set_frame_id("rig1_camera");
  return image;
}

v1::TrackFrame SomeTrackFrame(uint64_t frame_id) {
  v1::TrackFrame frame;
  frame.set_frame_id(frame_id);
  frame.set_capture_unix_time_ns(1700000000123456789);
  frame.set_image_width(640);
  frame.set_image_height(480);
  return frame;
}

// ---- the test client itself

TEST(WsClient, AcceptKeyMatchesTheRfc6455Example) {
  // RFC 6455 section 1.3.
  EXPECT_EQ(stevi::testing::WebSocketAccept("dGhlIHNhbXBsZSBub25jZQ=="),
            "s3pPLMBiTxaQ9kYGzzhZRbK+xOo=");
}

TEST(WsClient, Base64RoundTripsAndRejectsMalformedText) {
  for (const std::string text : {"", "f", "fo", "foo", "foob", "fooba", "foobar"}) {
    const std::string encoded = stevi::testing::Base64Encode(text);
    EXPECT_EQ(stevi::testing::Base64Decode(encoded), text) << encoded;
  }
  EXPECT_EQ(stevi::testing::Base64Encode("foobar"), "Zm9vYmFy");  // RFC 4648 section 10
  EXPECT_EQ(stevi::testing::Base64Encode("fo"), "Zm8=");
  EXPECT_FALSE(stevi::testing::Base64Decode("Zm9").has_value());
  EXPECT_FALSE(stevi::testing::Base64Decode("Zm=v").has_value());
  EXPECT_FALSE(stevi::testing::Base64Decode("Zm9*").has_value());
}

// ---- handshake

TEST(FoxgloveServer, EchoesTheFirstSubprotocolTheClientOffers) {
  std::unique_ptr<FoxgloveServer> server = StartServer();
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{kV1}, kV1},
      {{kSdk}, kSdk},
      {{kSdk, kV1}, kSdk},
      {{kV1, kSdk}, kV1},
      {{"x-other", kSdk}, kSdk},
  };
  for (const auto& [offered, expected] : cases) {
    WsOptions options;
    options.subprotocols = offered;
    std::unique_ptr<WsClient> client = Connect(*server, options);
    EXPECT_EQ(client->status(), 101) << offered[0];
    EXPECT_EQ(client->subprotocol(), expected) << offered[0];
    EXPECT_EQ(NextJson(*client).value("op", ""), "serverInfo");
  }
}

TEST(FoxgloveServer, RefusesAClientOfferingNeitherSubprotocol) {
  std::unique_ptr<FoxgloveServer> server = StartServer();
  for (const std::vector<std::string>& offered :
       {std::vector<std::string>{"foxglove.websocket.v2"}, std::vector<std::string>{}}) {
    WsOptions options;
    options.subprotocols = offered;  // empty: no Sec-WebSocket-Protocol header at all
    std::string error;
    std::unique_ptr<WsClient> client =
        WsClient::Connect("127.0.0.1", server->port(), options, error);
    ASSERT_NE(client, nullptr) << error;
    EXPECT_EQ(client->status(), 400);
    EXPECT_FALSE(client->open());
    EXPECT_THAT(client->response_body(), HasSubstr("foxglove.websocket.v1"));
  }
  EXPECT_EQ(server->stats().clients, 0u);
}

// ---- serverInfo and advertise

TEST(FoxgloveServer, SendsServerInfoFirstThenEveryChannel) {
  FoxgloveServerOptions options;
  options.name = "test station";
  std::unique_ptr<FoxgloveServer> server = StartServer(options);
  std::unique_ptr<WsClient> client = Connect(*server);
  const Json info = NextJson(*client);
  EXPECT_EQ(info.value("op", ""), "serverInfo");
  EXPECT_EQ(info.value("name", ""), "test station");
  ASSERT_TRUE(info.contains("capabilities"));
  EXPECT_TRUE(info["capabilities"].is_array());
  EXPECT_TRUE(info["capabilities"].empty());
  ASSERT_TRUE(info.contains("sessionId"));
  EXPECT_TRUE(info["sessionId"].is_string());
  EXPECT_FALSE(info["sessionId"].get<std::string>().empty());

  // Without channels nothing else is sent: a new channel's advertise is the next message.
  const uint32_t id = server->AddChannel(Spec("/a", foxglove::CompressedImage::descriptor()));
  const Json advertise = NextJson(*client);
  EXPECT_EQ(advertise.value("op", ""), "advertise");
  ASSERT_EQ(advertise["channels"].size(), 1u);
  EXPECT_EQ(advertise["channels"][0].value("id", 0u), id);

  // A later client gets serverInfo (same session) and one advertise with every channel.
  server->AddChannel(Spec("/b", v1::TrackFrame::descriptor()));
  std::unique_ptr<WsClient> later = Connect(*server);
  const Json later_info = NextJson(*later);
  EXPECT_EQ(later_info.value("op", ""), "serverInfo");
  EXPECT_EQ(later_info.value("sessionId", ""), info.value("sessionId", "?"));
  const Json later_advertise = NextJson(*later);
  EXPECT_EQ(later_advertise.value("op", ""), "advertise");
  EXPECT_EQ(later_advertise["channels"].size(), 2u);
}

TEST(FoxgloveServer, AdvertisesSchemasThatBuildInAFreshDescriptorPool) {
  std::unique_ptr<FoxgloveServer> server = StartServer();
  const std::vector<const google::protobuf::Descriptor*> descriptors = {
      foxglove::CompressedImage::descriptor(), v1::TrackFrame::descriptor(),
      foxglove::SceneUpdate::descriptor(), foxglove::ImageAnnotations::descriptor(),
      foxglove::LocationFix::descriptor()};
  std::vector<uint32_t> ids;
  for (size_t i = 0; i < descriptors.size(); ++i) {
    ids.push_back(server->AddChannel(
        Spec("/rig1/topic" + std::to_string(i), descriptors[i], /*lossy=*/i == 0)));
  }
  std::unique_ptr<WsClient> client = Connect(*server);
  ASSERT_EQ(NextJson(*client).value("op", ""), "serverInfo");
  const Json advertise = NextJson(*client);
  ASSERT_EQ(advertise.value("op", ""), "advertise");
  ASSERT_EQ(advertise["channels"].size(), descriptors.size());
  for (size_t i = 0; i < descriptors.size(); ++i) {
    const Json& channel = advertise["channels"][i];
    SCOPED_TRACE(descriptors[i]->full_name());
    EXPECT_EQ(channel.value("id", 0u), ids[i]);
    EXPECT_EQ(channel.value("topic", ""), "/rig1/topic" + std::to_string(i));
    EXPECT_EQ(channel.value("encoding", ""), "protobuf");
    EXPECT_EQ(channel.value("schemaName", ""), descriptors[i]->full_name());
    EXPECT_EQ(channel.value("schemaEncoding", ""), "protobuf");
    const std::optional<std::string> bytes =
        stevi::testing::Base64Decode(channel.value("schema", ""));
    ASSERT_TRUE(bytes.has_value()) << "schema is not base64";
    google::protobuf::FileDescriptorSet set;
    ASSERT_TRUE(set.ParseFromString(*bytes));
    // Each file builds after the ones before it: dependencies come first.
    google::protobuf::DescriptorPool pool;
    for (const google::protobuf::FileDescriptorProto& file : set.file()) {
      ASSERT_NE(pool.BuildFile(file), nullptr) << file.name();
    }
    const google::protobuf::Descriptor* built =
        pool.FindMessageTypeByName(channel.value("schemaName", ""));
    ASSERT_NE(built, nullptr);
    EXPECT_EQ(built->DebugString(), descriptors[i]->DebugString());
  }
}

TEST(FileDescriptorSetFor, ListsEveryDependencyOnceBeforeItsImporters) {
  google::protobuf::FileDescriptorSet set;
  ASSERT_TRUE(set.ParseFromString(FileDescriptorSetFor(foxglove::SceneUpdate::descriptor())));
  std::vector<std::string> names;
  for (const auto& file : set.file()) names.push_back(file.name());
  EXPECT_EQ(names.back(), "foxglove/SceneUpdate.proto");
  EXPECT_THAT(names,
              ::testing::IsSupersetOf(
                  {"google/protobuf/timestamp.proto", "google/protobuf/duration.proto",
                   "foxglove/SceneEntity.proto", "foxglove/Pose.proto", "foxglove/Color.proto"}));
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()).size(), names.size());
  for (int i = 0; i < set.file_size(); ++i) {
    for (const std::string& dependency : set.file(i).dependency()) {
      const auto at = std::find(names.begin(), names.end(), dependency);
      ASSERT_NE(at, names.end()) << dependency;
      EXPECT_LT(at - names.begin(), i) << dependency << " after " << names[size_t(i)];
    }
  }
}

// ---- subscriptions and message data

TEST(FoxgloveServer, SendsMessageDataOnlyToSubscribers) {
  SubscriptionLog log;  // outlives the server, whose Stop() calls the listener
  std::unique_ptr<FoxgloveServer> server = StartServer(log);
  const uint32_t images =
      server->AddChannel(Spec("/rig1/image", foxglove::CompressedImage::descriptor(), true));
  const uint32_t tracks = server->AddChannel(Spec("/rig1/tracks", v1::TrackFrame::descriptor()));
  std::unique_ptr<WsClient> both = ConnectAndGreet(*server, true);
  std::unique_ptr<WsClient> tracks_only = ConnectAndGreet(*server, true);

  Subscribe(*tracks_only, {{3, tracks}});
  ASSERT_TRUE(log.Next(tracks, true));
  Subscribe(*both, {{7, images}, {8, tracks}});  // one message: processed together
  ASSERT_TRUE(log.Next(images, true));
  EXPECT_TRUE(server->HasSubscribers(images));
  EXPECT_TRUE(server->HasSubscribers(tracks));

  const foxglove::CompressedImage image = SomeImage();
  const v1::TrackFrame frame = SomeTrackFrame(42);
  server->Publish(images, 0x0102030405060708ull, image.SerializeAsString());
  server->Publish(tracks, 42, frame.SerializeAsString());

  // The exact bytes of the first frame's 13-byte header.
  const std::optional<WsMessage> raw = both->Receive(kTimeout);
  ASSERT_TRUE(raw.has_value());
  ASSERT_EQ(raw->opcode, WsMessage::kBinary);
  ASSERT_GE(raw->payload.size(), 13u);
  const std::string header = raw->payload.substr(0, 13);
  EXPECT_EQ(header, std::string("\x01\x07\x00\x00\x00\x08\x07\x06\x05\x04\x03\x02\x01", 13));
  foxglove::CompressedImage got_image;
  ASSERT_TRUE(got_image.ParseFromString(raw->payload.substr(13)));
  EXPECT_EQ(got_image.SerializeAsString(), image.SerializeAsString());
  EXPECT_EQ(got_image.frame_id(), "rig1_camera");

  const std::optional<DataFrame> second = NextData(*both);
  ASSERT_TRUE(second.has_value());
  EXPECT_EQ(second->subscription, 8u);
  EXPECT_EQ(second->log_time_ns, 42u);
  v1::TrackFrame got_frame;
  ASSERT_TRUE(got_frame.ParseFromString(second->payload));
  EXPECT_EQ(got_frame.frame_id(), 42u);

  // The client not subscribed to the images gets the tracks first, under its own id.
  std::optional<DataFrame> only = NextData(*tracks_only);
  ASSERT_TRUE(only.has_value());
  EXPECT_EQ(only->subscription, 3u);
  EXPECT_EQ(only->log_time_ns, 42u);
  server->Publish(images, 43, image.SerializeAsString());
  server->Publish(tracks, 44, SomeTrackFrame(44).SerializeAsString());
  only = NextData(*tracks_only);
  ASSERT_TRUE(only.has_value());
  EXPECT_EQ(only->subscription, 3u);
  EXPECT_EQ(only->log_time_ns, 44u);
}

TEST(FoxgloveServer, StopsSendingAfterUnsubscribe) {
  SubscriptionLog log;  // outlives the server, whose Stop() calls the listener
  std::unique_ptr<FoxgloveServer> server = StartServer(log);
  const uint32_t a = server->AddChannel(Spec("/a", v1::TrackFrame::descriptor()));
  const uint32_t b = server->AddChannel(Spec("/b", v1::TrackFrame::descriptor()));
  std::unique_ptr<WsClient> client = ConnectAndGreet(*server, true);
  Subscribe(*client, {{1, a}});
  ASSERT_TRUE(log.Next(a, true));
  server->Publish(a, 1, SomeTrackFrame(1).SerializeAsString());
  std::optional<DataFrame> frame = NextData(*client);
  ASSERT_TRUE(frame.has_value());
  EXPECT_EQ(frame->subscription, 1u);

  // Unsubscribe, then subscribe to another channel: once that subscription is seen, the
  // unsubscribe before it has been processed.
  Unsubscribe(*client, {1});
  Subscribe(*client, {{2, b}});
  ASSERT_TRUE(log.Next(a, false));
  ASSERT_TRUE(log.Next(b, true));
  EXPECT_FALSE(server->HasSubscribers(a));
  for (uint64_t i = 10; i < 20; ++i) {
    server->Publish(a, i, SomeTrackFrame(i).SerializeAsString());
    server->Publish(b, i, SomeTrackFrame(i).SerializeAsString());
  }
  for (uint64_t i = 10; i < 20; ++i) {
    frame = NextData(*client);
    ASSERT_TRUE(frame.has_value());
    EXPECT_EQ(frame->subscription, 2u);
    EXPECT_EQ(frame->log_time_ns, i);
  }
  // The freed id can be used again.
  Subscribe(*client, {{1, a}});
  ASSERT_TRUE(log.Next(a, true));
}

TEST(FoxgloveServer, TellsTheListenerAboutFirstAndLastSubscribersOnly) {
  SubscriptionLog log;  // outlives the server, whose Stop() calls the listener
  std::unique_ptr<FoxgloveServer> server = StartServer(log);
  const uint32_t a = server->AddChannel(Spec("/a", v1::TrackFrame::descriptor()));
  const uint32_t sync1 = server->AddChannel(Spec("/sync1", v1::TrackFrame::descriptor()));
  const uint32_t sync2 = server->AddChannel(Spec("/sync2", v1::TrackFrame::descriptor()));
  std::unique_ptr<WsClient> first = ConnectAndGreet(*server, true);
  std::unique_ptr<WsClient> second = ConnectAndGreet(*server, true);
  Subscribe(*first, {{1, a}});
  ASSERT_TRUE(log.Next(a, true));
  // A second subscriber of `a` is no event; sync1's shows that it has been processed (one
  // message).
  Subscribe(*second, {{1, a}, {2, sync1}});
  ASSERT_TRUE(log.Next(sync1, true));
  // Nor is the first one leaving: the next event is sync2's, sent after the unsubscribe.
  Unsubscribe(*first, {1});
  Subscribe(*first, {{2, sync2}});
  ASSERT_TRUE(log.Next(sync2, true));
  EXPECT_TRUE(server->HasSubscribers(a));
  // A disconnect ends the last subscriptions of `a` and sync1 (in subscription id order).
  second->Abort();
  ASSERT_TRUE(log.Next(a, false));
  ASSERT_TRUE(log.Next(sync1, false));
  EXPECT_FALSE(server->HasSubscribers(a));
  EXPECT_EQ(log.size(), 5u);
}

TEST(FoxgloveServer, AdvertisesAddedChannelsAndUnadvertisesRemovedOnes) {
  SubscriptionLog log;  // outlives the server, whose Stop() calls the listener
  std::unique_ptr<FoxgloveServer> server = StartServer(log);
  std::unique_ptr<WsClient> client = ConnectAndGreet(*server, false);

  const uint32_t id = server->AddChannel(Spec("/rig2/scene", foxglove::SceneUpdate::descriptor()));
  const Json advertise = NextJson(*client);
  ASSERT_EQ(advertise.value("op", ""), "advertise");
  ASSERT_EQ(advertise["channels"].size(), 1u);
  EXPECT_EQ(advertise["channels"][0].value("id", 0u), id);
  EXPECT_EQ(advertise["channels"][0].value("topic", ""), "/rig2/scene");
  EXPECT_EQ(advertise["channels"][0].value("schemaName", ""), "foxglove.SceneUpdate");

  Subscribe(*client, {{5, id}});
  ASSERT_TRUE(log.Next(id, true));
  server->RemoveChannel(id);
  ASSERT_TRUE(log.Next(id, false));  // on this thread, before RemoveChannel returns
  EXPECT_FALSE(server->HasSubscribers(id));
  const Json unadvertise = NextJson(*client);
  EXPECT_EQ(unadvertise.value("op", ""), "unadvertise");
  EXPECT_EQ(unadvertise["channelIds"], Json::array({id}));

  // The channel is gone for subscribing, and its id is not reused.
  Subscribe(*client, {{6, id}});
  EXPECT_THAT(NextWarning(*client), HasSubstr("unknown channel " + std::to_string(id)));
  EXPECT_NE(server->AddChannel(Spec("/rig2/scene", foxglove::SceneUpdate::descriptor())), id);
}

TEST(FoxgloveServer, SendStatusReachesEveryClient) {
  std::unique_ptr<FoxgloveServer> server = StartServer();
  std::unique_ptr<WsClient> a = ConnectAndGreet(*server, false);
  std::unique_ptr<WsClient> b = ConnectAndGreet(*server, false);
  server->SendStatus(2, "rig1 is down", "rig1");
  for (WsClient* client : {a.get(), b.get()}) {
    EXPECT_EQ(NextJson(*client),
              (Json{{"op", "status"}, {"level", 2}, {"message", "rig1 is down"}, {"id", "rig1"}}));
  }
}

// ---- untrusted input

TEST(FoxgloveServer, WarnsAboutBadMessagesAndKeepsTheConnection) {
  SubscriptionLog log;  // outlives the server, whose Stop() calls the listener
  std::unique_ptr<FoxgloveServer> server = StartServer(log);
  const uint32_t a = server->AddChannel(Spec("/a", v1::TrackFrame::descriptor()));
  const uint32_t b = server->AddChannel(Spec("/b", v1::TrackFrame::descriptor()));
  std::unique_ptr<WsClient> client = ConnectAndGreet(*server, true);

  const std::vector<std::pair<std::string, std::string>> cases = {
      {"{not json", "malformed JSON"},
      {"[1, 2]", "must be a JSON object"},
      {R"({"subscriptions": []})", "\"op\""},
      {R"({"op": 7})", "\"op\""},
      {R"({"op": "frobnicate"})", "unknown op \"frobnicate\""},
      {R"({"op": "advertise", "channels": []})", "unsupported op \"advertise\""},
      {R"({"op": "subscribe", "subscriptions": "all"})", "\"subscriptions\" must be an array"},
      {R"({"op": "subscribe", "subscriptions": [{"id": "x", "channelId": 1}]})", "integers"},
      {R"({"op": "subscribe", "subscriptions": [{"id": -1, "channelId": 1}]})", "integers"},
      {R"({"op": "subscribe", "subscriptions": [{"id": 4294967296, "channelId": 1}]})", "integers"},
      {R"({"op": "subscribe", "subscriptions": [{"id": 1.5, "channelId": 1}]})", "integers"},
      {R"({"op": "subscribe", "subscriptions": [{"id": 1}]})", "\"channelId\""},
      {R"({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 999}]})",
       "unknown channel 999"},
      {R"({"op": "unsubscribe", "subscriptionIds": [77]})", "unknown subscription id 77"},
      {R"({"op": "unsubscribe", "subscriptionIds": {}})", "\"subscriptionIds\" must be an array"},
      {"\"\xff\xfe\"", "malformed JSON"},
  };
  for (const auto& [text, expected] : cases) {
    ASSERT_TRUE(client->SendText(text));
    EXPECT_THAT(NextWarning(*client), HasSubstr(expected)) << "sent: " << text;
  }
  // Binary client messages (no clientPublish).
  ASSERT_TRUE(client->SendBinary(std::string("\x01\x01\x00\x00\x00payload", 12)));
  EXPECT_THAT(NextWarning(*client), HasSubstr("clientPublish"));

  // Duplicate subscription ids and channels.
  Subscribe(*client, {{1, a}});
  ASSERT_TRUE(log.Next(a, true));
  Subscribe(*client, {{1, b}});
  EXPECT_THAT(NextWarning(*client), HasSubstr("subscription id 1 is already in use"));
  Subscribe(*client, {{2, a}});
  EXPECT_THAT(NextWarning(*client),
              HasSubstr("already subscribed to channel " + std::to_string(a)));

  // Still usable.
  server->Publish(a, 5, SomeTrackFrame(5).SerializeAsString());
  const std::optional<DataFrame> frame = NextData(*client);
  ASSERT_TRUE(frame.has_value());
  EXPECT_EQ(frame->subscription, 1u);
  EXPECT_FALSE(server->HasSubscribers(b));
}

TEST(FoxgloveServer, ReassemblesFragmentedMessages) {
  std::unique_ptr<FoxgloveServer> server = StartServer();
  std::unique_ptr<WsClient> client = ConnectAndGreet(*server, false);
  ASSERT_TRUE(client->SendFrame(WsMessage::kText, R"({"op": "frob)", false));
  ASSERT_TRUE(client->SendFrame(0x0, "nic", false));
  ASSERT_TRUE(client->SendFrame(0x0, R"(ate"})", true));
  EXPECT_THAT(NextWarning(*client), HasSubstr("unknown op \"frobnicate\""));
}

// The closing handshake (RFC 6455 5.5.1): a client's Close is answered with a Close echoing its
// status code, so that browsers and Foxglove see a clean close (1000), not 1006.
TEST(FoxgloveServer, AnswersTheClientsCloseWithACloseEchoingItsCode) {
  std::unique_ptr<FoxgloveServer> server = StartServer({});
  for (const uint16_t code : {1000, 1001}) {
    std::unique_ptr<WsClient> client = ConnectAndGreet(*server, false);
    ASSERT_TRUE(client->SendClose(code));
    std::optional<WsMessage> answer;
    do {
      answer = client->Receive(kTimeout);
    } while (answer && answer->opcode != WsMessage::kClose && answer->opcode != WsMessage::kEnd);
    ASSERT_TRUE(answer.has_value());
    EXPECT_EQ(answer->opcode, WsMessage::kClose) << "the connection ended without a Close";
    EXPECT_EQ(answer->close_code(), code);
  }
  EXPECT_TRUE(Eventually([&] { return server->stats().clients == 0; }));
}

// A Close whose body cannot be echoed (RFC 6455 7.4): one byte (no whole status code), or a code
// no endpoint may send (1005, 1006, 1015 only report; 0..999, 1016..2999 and 5000 and up are not
// defined). It is answered with 1002 (protocol error), not echoed into a malformed Close; an empty
// body gets an empty one. (Found by tests/fuzz/foxglove_ws: the server echoed "\x03".)
TEST(FoxgloveServer, AnswersACloseItCannotEchoWithProtocolError) {
  std::unique_ptr<FoxgloveServer> server = StartServer({});
  const std::pair<std::string, int> cases[] = {
      {std::string("\x03", 1), 1002},      // a byte: no whole code
      {std::string("\x03\xed", 2), 1002},  // 1005
      {std::string("\x03\xee", 2), 1002},  // 1006
      {std::string("\x03\xf7", 2), 1002},  // 1015
      {std::string("\x00\x00", 2), 1002},  // 0
      {std::string("\x13\x88", 2), 1002},  // 5000
      {std::string("\x03\xe9 bye", 6), 1001},
      {std::string("\x0f\xa0", 2), 4000},
      {std::string(), 0},  // no code: an empty Close
  };
  for (const auto& [body, answer] : cases) {
    SCOPED_TRACE(::testing::PrintToString(body));
    std::unique_ptr<WsClient> client = ConnectAndGreet(*server, false);
    ASSERT_TRUE(client->SendFrame(WsMessage::kClose, body, true));
    std::optional<WsMessage> reply;
    do {
      reply = client->Receive(kTimeout);
    } while (reply && reply->opcode != WsMessage::kClose && reply->opcode != WsMessage::kEnd);
    ASSERT_TRUE(reply.has_value());
    ASSERT_EQ(reply->opcode, WsMessage::kClose);
    EXPECT_EQ(reply->close_code(), answer);
    EXPECT_EQ(reply->payload.size(), answer == 0 ? 0u : 2u);

    // The same without a socket (FoxgloveServer::LocalClient, as the fuzz target drives it).
    std::unique_ptr<FoxgloveServer::LocalClient> local = server->ConnectLocal();
    EXPECT_FALSE(local->Receive(0x88, body));
    const std::vector<FoxgloveServer::LocalClient::Frame> sent = local->TakeSent();
    ASSERT_FALSE(sent.empty());
    EXPECT_EQ(sent.back().opcode, WsMessage::kClose);
    const std::string expected =
        answer == 0 ? "" : std::string{char(answer >> 8), char(answer & 0xff)};
    EXPECT_EQ(sent.back().payload, expected);
  }
}

TEST(FoxgloveServer, ClosesAConnectionThatSendsAnOversizeMessage) {
  FoxgloveServerOptions options;
  options.max_incoming_message_bytes = 1024;
  std::unique_ptr<FoxgloveServer> server = StartServer(options);

  // Exactly the limit is fine.
  std::unique_ptr<WsClient> client = ConnectAndGreet(*server, false);
  std::string at_limit = R"({"op": "frobnicate")";
  at_limit += std::string(1024 - at_limit.size() - 1, ' ') + "}";
  ASSERT_EQ(at_limit.size(), 1024u);
  ASSERT_TRUE(client->SendText(at_limit));
  EXPECT_THAT(NextWarning(*client), HasSubstr("frobnicate"));

  // One frame, then fragments, over the limit.
  for (bool fragmented : {false, true}) {
    SCOPED_TRACE(fragmented ? "fragmented" : "one frame");
    std::unique_ptr<WsClient> big = ConnectAndGreet(*server, false);
    if (fragmented) {
      ASSERT_TRUE(big->SendFrame(WsMessage::kText, std::string(600, ' '), false));
      big->SendFrame(0x0, std::string(600, ' '), true);
    } else {
      big->SendText(std::string(1025, ' '));
    }
    const std::optional<WsMessage> end = big->Receive(kTimeout);
    ASSERT_TRUE(end.has_value());
    EXPECT_EQ(end->opcode, WsMessage::kClose);
    EXPECT_EQ(end->close_code(), 1009);  // "message too big"
    EXPECT_THAT(end->payload.substr(2), HasSubstr("1024"));
  }
  EXPECT_TRUE(Eventually([&] { return server->stats().clients == 1; }));
  // The well-behaved client is untouched.
  server->SendStatus(0, "still here");
  EXPECT_EQ(NextJson(*client).value("message", ""), "still here");
}

// ---- limits

TEST(FoxgloveServer, RefusesClientsBeyondMaxClients) {
  FoxgloveServerOptions options;
  options.max_clients = 2;
  std::unique_ptr<FoxgloveServer> server = StartServer(options);
  std::unique_ptr<WsClient> a = ConnectAndGreet(*server, false);
  std::unique_ptr<WsClient> b = ConnectAndGreet(*server, false);
  std::unique_ptr<WsClient> refused = Connect(*server);
  EXPECT_EQ(refused->status(), 503);
  EXPECT_FALSE(refused->open());
  EXPECT_EQ(server->stats().clients, 2u);

  // HTTP still works while the WebSocket slots are full.
  server->AddHttpHandler("/", [](const HttpRequest&) { return HttpResponse{200, "text/plain"}; });
  const std::optional<HttpReply> page = Http(*server, "GET", "/");
  ASSERT_TRUE(page.has_value());
  EXPECT_EQ(page->status, 200);

  // A slot freed by a disconnect is taken again.
  a->Abort();
  ASSERT_TRUE(Eventually([&] { return server->stats().clients == 1; }));
  std::unique_ptr<WsClient> c = ConnectAndGreet(*server, false);
  EXPECT_TRUE(c->open());
}

TEST(FoxgloveServer, NeedsTheAccessTokenWhenConfigured) {
  FoxgloveServerOptions options;
  options.access_token = "s3cret";
  std::unique_ptr<FoxgloveServer> server = StartServer(options);
  server->AddHttpHandler("/", [](const HttpRequest&) {
    return HttpResponse{200, "text/html", "<html></html>"};
  });
  server->AddHttpHandler("/api/", [](const HttpRequest&) {
    return HttpResponse{200, "application/json", "{}"};
  });

  const auto ws = [&](const std::string& path,
                      std::vector<std::pair<std::string, std::string>> headers = {}) {
    WsOptions ws_options;
    ws_options.path = path;
    ws_options.headers = std::move(headers);
    return Connect(*server, ws_options)->status();
  };
  EXPECT_EQ(ws("/"), 401);
  EXPECT_EQ(ws("/?token=wrong"), 403);
  EXPECT_EQ(ws("/?token="), 403);
  EXPECT_EQ(ws("/?token=s3cret"), 101);
  EXPECT_EQ(ws("/?x=1&token=s3cret"), 101);
  EXPECT_EQ(ws("/", {{"Authorization", "Bearer s3cret"}}), 101);
  EXPECT_EQ(ws("/", {{"Authorization", "Bearer s3cre"}}), 403);

  const auto http = [&](const std::string& path,
                        std::vector<std::pair<std::string, std::string>> headers = {}) {
    const std::optional<HttpReply> reply = Http(*server, "GET", path, headers);
    return reply ? reply->status : 0;
  };
  EXPECT_EQ(http("/api/rigs"), 401);
  EXPECT_EQ(http("/api/rigs", {{"Authorization", "Bearer nope"}}), 403);
  EXPECT_EQ(http("/api/rigs?token=s3cret"), 401);  // the API takes the header only
  EXPECT_EQ(http("/api/rigs", {{"Authorization", "Bearer s3cret"}}), 200);
  EXPECT_EQ(http("/"), 200);  // static pages stay open
  EXPECT_EQ(http("/app.js"), 200);
}

TEST(FoxgloveServer, SlowClientDropsLossyMessagesFirstAndDoesNotStallOthers) {
  FoxgloveServerOptions options;
  // Room for every track frame of the test (16) but for only 3 images (1 MiB).
  options.queue_messages = 32;
  options.queue_bytes = 1 << 20;
  SubscriptionLog log;  // outlives the server, whose Stop() calls the listener
  std::unique_ptr<FoxgloveServer> server = StartServer(log, options);
  const uint32_t images =
      server->AddChannel(Spec("/image", foxglove::CompressedImage::descriptor(), true));
  const uint32_t tracks = server->AddChannel(Spec("/tracks", v1::TrackFrame::descriptor()));
  std::unique_ptr<WsClient> fast = ConnectAndGreet(*server, true);
  std::unique_ptr<WsClient> slow = ConnectAndGreet(*server, true);
  Subscribe(*fast, {{1, images}});
  ASSERT_TRUE(log.Next(images, true));
  Subscribe(*slow, {{1, images}, {2, tracks}});
  ASSERT_TRUE(log.Next(tracks, true));

  // 160 images of 256 KiB (40 MiB: more than loopback's socket buffers hold) and a track frame
  // after every tenth. The fast client reads each image before the next is published.
  constexpr uint64_t kImages = 160;
  std::string image(256 << 10, 'x');
  for (uint64_t i = 0; i < kImages; ++i) {
    image.replace(0, 8, std::to_string(10000000 + i));
    server->Publish(images, i, image);
    if (i % 10 == 9) server->Publish(tracks, i, SomeTrackFrame(i).SerializeAsString());
    const std::optional<DataFrame> frame = NextData(*fast);
    ASSERT_TRUE(frame.has_value()) << "image " << i;
    ASSERT_EQ(frame->subscription, 1u);
    ASSERT_EQ(frame->log_time_ns, i);
    ASSERT_EQ(frame->payload.size(), image.size());
  }
  const uint64_t dropped = server->stats().messages_dropped;
  EXPECT_GT(dropped, 0u);

  // The slow client now reads: every track frame arrives (images were dropped instead: the queue
  // was never full of track frames), images in order with gaps, the newest one included, and the
  // drops are exactly the missing images.
  std::vector<uint64_t> slow_images;
  std::vector<uint64_t> slow_tracks;
  while (slow_tracks.empty() || slow_tracks.back() != kImages - 1 || slow_images.empty() ||
         slow_images.back() != kImages - 1) {
    const std::optional<DataFrame> frame = NextData(*slow);
    ASSERT_TRUE(frame.has_value())
        << slow_images.size() << " images (last " << (slow_images.empty() ? 0 : slow_images.back())
        << "), " << slow_tracks.size() << " track frames so far; server sent "
        << server->stats().messages_sent << ", dropped " << server->stats().messages_dropped;
    (frame->subscription == 1 ? slow_images : slow_tracks).push_back(frame->log_time_ns);
  }
  std::vector<uint64_t> expected_tracks;
  for (uint64_t i = 9; i < kImages; i += 10) expected_tracks.push_back(i);
  EXPECT_EQ(slow_tracks, expected_tracks);
  EXPECT_TRUE(std::is_sorted(slow_images.begin(), slow_images.end()));
  EXPECT_LT(slow_images.size(), kImages);
  EXPECT_EQ(dropped, kImages - slow_images.size());
  EXPECT_EQ(server->stats().messages_dropped, dropped);
}

// ---- HTTP

TEST(FoxgloveServer, RoutesHttpByLongestPrefixBesideTheWebSocket) {
  std::unique_ptr<FoxgloveServer> server = StartServer();
  const auto named = [](std::string name) {
    return [name](const HttpRequest&) { return HttpResponse{200, "text/plain", name}; };
  };
  server->AddHttpHandler("/", named("root"));
  server->AddHttpHandler("/api/", named("api"));
  server->AddHttpHandler("/api/rigs/", named("rigs"));
  server->AddHttpHandler("/api/echo", [](const HttpRequest& request) {
    HttpResponse response;
    response.status = 201;
    response.content_type = "text/plain";
    response.body = request.method + "|" + request.path + "|" + request.query + "|" + request.body +
                    "|" + request.headers.at("x-test");
    response.headers.emplace_back("X-Reply", "yes");
    response.headers.emplace_back("X-Bad", "split\r\nInjected: 1");
    return response;
  });
  server->AddHttpHandler("/api/throw", [](const HttpRequest&) -> HttpResponse {
    throw std::runtime_error("handler failed");
  });
  // A WebSocket on "/" at the same time as plain GETs of "/".
  std::unique_ptr<WsClient> ws = ConnectAndGreet(*server, false);

  const std::vector<std::pair<std::string, std::string>> routes = {
      {"/", "root"},          {"/?a=1", "root"},
      {"/app.js", "root"},    {"/apix", "root"},
      {"/api/", "api"},       {"/api/status", "api"},
      {"/api/rigs/", "rigs"}, {"/api/rigs/rig1/config", "rigs"}};
  for (const auto& [path, expected] : routes) {
    const std::optional<HttpReply> reply = Http(*server, "GET", path);
    ASSERT_TRUE(reply.has_value());
    EXPECT_EQ(reply->status, 200) << path;
    EXPECT_EQ(reply->body, expected) << path;
  }

  const std::optional<HttpReply> echo =
      Http(*server, "POST", "/api/echo?x=1%202", {{"X-Test", "Value"}}, "hello body");
  ASSERT_TRUE(echo.has_value());
  EXPECT_EQ(echo->status, 201);
  EXPECT_EQ(echo->body, "POST|/api/echo|x=1%202|hello body|Value");
  EXPECT_EQ(echo->headers.at("content-type"), "text/plain");
  EXPECT_EQ(echo->headers.at("x-reply"), "yes");
  EXPECT_FALSE(echo->headers.contains("x-bad"));
  EXPECT_FALSE(echo->headers.contains("injected"));

  const std::optional<HttpReply> thrown = Http(*server, "GET", "/api/throw");
  ASSERT_TRUE(thrown.has_value());
  EXPECT_EQ(thrown->status, 500);
  EXPECT_THAT(thrown->body, HasSubstr("handler failed"));

  // The WebSocket was not disturbed.
  server->SendStatus(0, "after http");
  EXPECT_EQ(NextJson(*ws).value("message", ""), "after http");
}

TEST(FoxgloveServer, AnswersNotFoundWithoutAHandler) {
  std::unique_ptr<FoxgloveServer> server = StartServer();
  server->AddHttpHandler("/api/", [](const HttpRequest&) { return HttpResponse{}; });
  const std::optional<HttpReply> reply = Http(*server, "GET", "/index.html");
  ASSERT_TRUE(reply.has_value());
  EXPECT_EQ(reply->status, 404);
  EXPECT_EQ(Json::parse(reply->body).value("code", ""), "NOT_FOUND");
}

TEST(FoxgloveServer, RefusesOversizeRequestBodiesWith413) {
  FoxgloveServerOptions options;
  options.max_request_body_bytes = 1000;
  std::unique_ptr<FoxgloveServer> server = StartServer(options);
  server->AddHttpHandler("/", [](const HttpRequest& request) {
    return HttpResponse{200, "text/plain", std::to_string(request.body.size())};
  });
  const std::optional<HttpReply> fits = Http(*server, "POST", "/x", {}, std::string(1000, 'a'));
  ASSERT_TRUE(fits.has_value());
  EXPECT_EQ(fits->status, 200);
  EXPECT_EQ(fits->body, "1000");
  for (size_t size : {size_t(1001), size_t(4) << 20}) {
    const std::optional<HttpReply> big = Http(*server, "POST", "/x", {}, std::string(size, 'a'));
    ASSERT_TRUE(big.has_value());
    EXPECT_EQ(big->status, 413) << size;
    EXPECT_EQ(Json::parse(big->body).value("code", ""), "RESOURCE_EXHAUSTED");
  }
}

// ---- life cycle

TEST(FoxgloveServer, StartNamesABadOrBusyAddress) {
  std::string error;
  FoxgloveServerOptions options;
  for (const std::string listen :
       {"nonsense", "127.0.0.1:99999", "127.0.0.1:", "example.com:80", "[::1:80"}) {
    options.listen = listen;
    error.clear();
    EXPECT_EQ(FoxgloveServer::Start(options, error), nullptr) << listen;
    EXPECT_THAT(error, HasSubstr("\"" + listen + "\"")) << listen;
  }
  std::unique_ptr<FoxgloveServer> server = StartServer();
  options.listen = "127.0.0.1:" + std::to_string(server->port());
  error.clear();
  EXPECT_EQ(FoxgloveServer::Start(options, error), nullptr);
  EXPECT_THAT(error, HasSubstr(options.listen));
}

TEST(FoxgloveServer, StopClosesEveryClientAndJoins) {
  FoxgloveServerOptions options;
  options.queue_messages = 2;
  SubscriptionLog log;  // outlives the server, whose Stop() calls the listener
  std::unique_ptr<FoxgloveServer> server = StartServer(log, options);
  const uint32_t images =
      server->AddChannel(Spec("/image", foxglove::CompressedImage::descriptor(), true));
  std::unique_ptr<WsClient> reader = ConnectAndGreet(*server, true);
  std::unique_ptr<WsClient> stuck = ConnectAndGreet(*server, true);
  Subscribe(*stuck, {{1, images}});
  ASSERT_TRUE(log.Next(images, true));
  // Fill the stuck client's socket so that its sender blocks in a write.
  const std::string image(1 << 20, 'x');
  for (int i = 0; i < 32; ++i) server->Publish(images, uint64_t(i), image);

  const auto start = std::chrono::steady_clock::now();
  server->Stop();
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
  EXPECT_EQ(server->stats().clients, 0u);
  EXPECT_TRUE(log.Next(images, false));
  for (;;) {
    const std::optional<WsMessage> message = reader->Receive(kTimeout);
    ASSERT_TRUE(message.has_value());
    if (message->opcode == WsMessage::kClose || message->opcode == WsMessage::kEnd) break;
  }
  server->Stop();  // idempotent
  server->Publish(images, 0, "after stop");
  server.reset();
}

}  // namespace
}  // namespace stevi::station
