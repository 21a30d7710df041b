// Who may connect and who may control: TLS, mutual TLS, bearer tokens, and the loopback rule,
// through real gRPC channels to the server in-process. Certificates are made for each run with
// the openssl command-line tool (a throwaway CA, a server certificate for localhost and
// 127.0.0.1, and two client certificates).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <fstream>
#include <iostream>
#include <mutex>
#include <thread>
#include <vector>

#include "client/lib/client.h"
#include "server/app_config.h"
#include "server/auth.h"
#include "server/server.h"
#include "tests/testing/data.h"
#include "tests/testing/subprocess.h"

namespace stevi::server {
namespace {

using ::testing::HasSubstr;
constexpr char kToken[] = "0123456789abcdef-secret";

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// Runs openssl with `args`; fails the test with its output when it fails.
void OpenSsl(const std::vector<std::string>& args) {
  std::vector<std::string> argv{"/usr/bin/openssl"};
  argv.insert(argv.end(), args.begin(), args.end());
  const testing::RunResult r = testing::Run(argv, std::chrono::seconds(30));
  ASSERT_EQ(r.exit_code, 0) << "openssl " << ::testing::PrintToString(args) << ": " << r.err;
}

// A CA, a server certificate (localhost, 127.0.0.1) and client certificates, in one folder.
struct Pki {
  std::string dir;
  std::string ca() const { return dir + "/ca.pem"; }
  std::string cert(const std::string& name) const { return dir + "/" + name + ".pem"; }
  std::string key(const std::string& name) const { return dir + "/" + name + ".key"; }
};

void MakeCertificate(const Pki& pki, const std::string& name, const std::string& extensions) {
  ASSERT_NO_FATAL_FAILURE(OpenSsl(
      {"req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-keyout",
       pki.key(name), "-out", pki.dir + "/" + name + ".csr", "-subj", "/CN=" + name}));
  const std::string ext = pki.dir + "/" + name + ".ext";
  std::ofstream(ext) << extensions << "\n";
  ASSERT_NO_FATAL_FAILURE(OpenSsl({"x509", "-req", "-in", pki.dir + "/" + name + ".csr", "-CA",
                                   pki.ca(), "-CAkey", pki.dir + "/ca.key", "-CAcreateserial",
                                   "-out", pki.cert(name), "-days", "2", "-extfile", ext}));
}

Pki MakePki() {
  Pki pki{testing::MakeTempDir("stevi-pki")};
  OpenSsl({"req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
           "-keyout", pki.dir + "/ca.key", "-out", pki.ca(), "-days", "2", "-subj",
           "/CN=stevi test CA"});
  MakeCertificate(pki, "localhost", "subjectAltName=DNS:localhost,IP:127.0.0.1");
  MakeCertificate(pki, "autopilot", "extendedKeyUsage=clientAuth");
  MakeCertificate(pki, "intruder", "extendedKeyUsage=clientAuth");
  return pki;
}

v1::ServerConfig SecureConfig(const Pki& pki) {
  v1::ServerConfig config;
  config.set_listen("127.0.0.1:0");
  config.mutable_source()->set_fps(20);
  config.set_data_dir(testing::MakeTempDir("stevi-secure-data"));
  config.mutable_tls()->set_cert_file(pki.cert("localhost"));
  config.mutable_tls()->set_key_file(pki.key("localhost"));
  const std::string token_file = pki.dir + "/token";
  std::ofstream(token_file) << kToken << "\n";
  config.mutable_auth()->set_token_file(token_file);
  return config;
}

client::ClientOptions TlsClient(const Pki& pki, int port, const std::string& token = "",
                                const std::string& certificate = "") {
  client::ClientOptions options;
  options.address = "localhost:" + std::to_string(port);
  options.timeout = std::chrono::seconds(10);
  grpc::SslCredentialsOptions tls;
  tls.pem_root_certs = Slurp(pki.ca());
  if (!certificate.empty()) {
    tls.pem_cert_chain = Slurp(pki.cert(certificate));
    tls.pem_private_key = Slurp(pki.key(certificate));
  }
  options.credentials = grpc::SslCredentials(tls);
  options.bearer_token = token;
  return options;
}

// A config change only a controller may make.
grpc::Status SetAlgorithm(client::Client& c, v1::Algorithm algorithm) {
  v1::PipelineConfig update;
  update.set_algorithm(algorithm);
  v1::PipelineConfig active;
  return c.SetPipelineConfig(update, &active);
}

class SecurityTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { pki_ = new Pki(MakePki()); }
  static void TearDownTestSuite() { delete pki_; }
  static Pki* pki_;
};
Pki* SecurityTest::pki_ = nullptr;

TEST_F(SecurityTest, ControlCallsNeedTheTokenReadOnlyOnesDoNot) {
  ASSERT_FALSE(HasFailure());
  Result<std::unique_ptr<Server>> server = Server::Start(SecureConfig(*pki_));
  ASSERT_TRUE(server.ok()) << server.error().message;
  const int port = (*server)->port();

  client::Client anonymous(TlsClient(*pki_, port));
  v1::GetStatusResponse status;
  EXPECT_TRUE(anonymous.GetStatus(&status).ok()) << "status is read-only";
  v1::PipelineConfig config;
  EXPECT_TRUE(anonymous.GetPipelineConfig(&config).ok());

  const grpc::Status none = SetAlgorithm(anonymous, v1::ALGORITHM_STEVIS);
  EXPECT_EQ(none.error_code(), grpc::StatusCode::UNAUTHENTICATED) << none.error_message();
  EXPECT_THAT(none.error_message(), HasSubstr("SetPipelineConfig"));
  client::Client wrong(TlsClient(*pki_, port, "0123456789abcdef-guess"));
  EXPECT_EQ(SetAlgorithm(wrong, v1::ALGORITHM_STEVIS).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  // gRPC aborts the process on a metadata value that is not printable ASCII (the station's
  // fuzz target found it through an operator token): the client does not send such a token.
  client::Client binary(TlsClient(*pki_, port, "0123456789abcdef\xC9"));
  EXPECT_EQ(SetAlgorithm(binary, v1::ALGORITHM_STEVIS).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  client::Client prefix(TlsClient(*pki_, port, "0123456789abcdef"));
  EXPECT_EQ(SetAlgorithm(prefix, v1::ALGORITHM_STEVIS).error_code(),
            grpc::StatusCode::PERMISSION_DENIED)
      << "a prefix of the token is not the token";
  ASSERT_TRUE(anonymous.GetPipelineConfig(&config).ok());
  EXPECT_EQ(config.algorithm(), v1::ALGORITHM_CANONICAL) << "refused calls changed nothing";

  // Every control RPC is guarded, streams included.
  v1::RecordingStatus recording;
  EXPECT_EQ(anonymous.StartRecording(v1::StartRecordingRequest(), &recording).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(anonymous.StopRecording(&recording).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  v1::PublishVehicleStateResponse published;
  EXPECT_EQ(anonymous.PublishVehicleStates({v1::VehicleState()}, &published).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  v1::CalibrationSettings settings;
  v1::CalibrationReport report;
  EXPECT_EQ(anonymous.Calibrate(settings, {}, &report).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  v1::CaptureCalibrationRequest capture;
  EXPECT_EQ(anonymous.CaptureCalibration(capture, [](const v1::CaptureProgress&) {}).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  v1::CalibrationRecord record;
  EXPECT_EQ(anonymous.ActivateCalibration("cal-000001", &record).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  v1::ListCalibrationsResponse list;
  EXPECT_TRUE(anonymous.ListCalibrations(&list).ok()) << "listing is read-only";

  client::Client controller(TlsClient(*pki_, port, kToken));
  const grpc::Status allowed = SetAlgorithm(controller, v1::ALGORITHM_STEVIS);
  EXPECT_TRUE(allowed.ok()) << allowed.error_message();
  ASSERT_TRUE(anonymous.GetPipelineConfig(&config).ok());
  EXPECT_EQ(config.algorithm(), v1::ALGORITHM_STEVIS);

  // The port speaks TLS only.
  client::ClientOptions plain;
  plain.address = "127.0.0.1:" + std::to_string(port);
  plain.timeout = std::chrono::seconds(3);
  client::Client insecure(plain);
  EXPECT_EQ(insecure.GetStatus(&status).error_code(), grpc::StatusCode::UNAVAILABLE);
}

TEST_F(SecurityTest, MutualTlsAllowsNamedClientCertificates) {
  ASSERT_FALSE(HasFailure());
  v1::ServerConfig config = SecureConfig(*pki_);
  config.mutable_auth()->clear_token_file();
  config.mutable_tls()->set_client_ca_file(pki_->ca());
  config.mutable_auth()->add_allowed_client_names("autopilot");
  Result<std::unique_ptr<Server>> server = Server::Start(config);
  ASSERT_TRUE(server.ok()) << server.error().message;
  const int port = (*server)->port();

  client::Client autopilot(TlsClient(*pki_, port, "", "autopilot"));
  const grpc::Status allowed = SetAlgorithm(autopilot, v1::ALGORITHM_STEVIE);
  EXPECT_TRUE(allowed.ok()) << allowed.error_message();

  client::Client intruder(TlsClient(*pki_, port, "", "intruder"));
  v1::GetStatusResponse status;
  EXPECT_TRUE(intruder.GetStatus(&status).ok()) << "a verified client may read";
  const grpc::Status denied = SetAlgorithm(intruder, v1::ALGORITHM_STEVIS);
  EXPECT_EQ(denied.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_THAT(denied.error_message(), HasSubstr("intruder"));

  client::Client no_certificate(TlsClient(*pki_, port));
  EXPECT_EQ(no_certificate.GetStatus(&status).error_code(), grpc::StatusCode::UNAVAILABLE)
      << "mutual TLS: no certificate, no connection";
}

// A radio link on loopback: a TCP relay that holds every chunk `delay` before passing it on, in
// each direction. Each chunk is read only after the previous one was delivered, so a burst waits
// longer still, as on a narrow link.
class SlowLink {
 public:
  SlowLink(int upstream_port, std::chrono::milliseconds delay)
      : upstream_port_(upstream_port), delay_(delay) {
    listen_fd_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof(a);
    if (bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), len) != 0 || listen(listen_fd_, 8) != 0 ||
        getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
      ADD_FAILURE() << "SlowLink: cannot listen on loopback";
      return;
    }
    port_ = ntohs(a.sin_port);
    accept_thread_ = std::thread([this] { AcceptLoop(); });
  }
  ~SlowLink() {
    stop_ = true;
    shutdown(listen_fd_, SHUT_RDWR);
    {
      std::lock_guard lock(mu_);
      for (int fd : fds_) shutdown(fd, SHUT_RDWR);
    }
    if (accept_thread_.joinable()) accept_thread_.join();
    for (std::thread& t : pumps_) t.join();
    close(listen_fd_);
    for (int fd : fds_) close(fd);
  }
  int port() const { return port_; }

 private:
  void AcceptLoop() {
    while (!stop_) {
      pollfd p{listen_fd_, POLLIN, 0};
      if (poll(&p, 1, 100) <= 0) continue;
      const int in = accept(listen_fd_, nullptr, nullptr);
      if (in < 0) continue;
      const int out = socket(AF_INET, SOCK_STREAM, 0);
      sockaddr_in a{};
      a.sin_family = AF_INET;
      a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      a.sin_port = htons(static_cast<uint16_t>(upstream_port_));
      if (connect(out, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0) {
        close(in);
        close(out);
        continue;
      }
      std::lock_guard lock(mu_);
      fds_.push_back(in);
      fds_.push_back(out);
      pumps_.emplace_back([this, in, out] { Pump(in, out); });
      pumps_.emplace_back([this, in, out] { Pump(out, in); });
    }
  }
  void Pump(int from, int to) {
    char buffer[16384];
    while (!stop_) {
      const ssize_t n = recv(from, buffer, sizeof(buffer), 0);
      if (n <= 0) break;
      std::this_thread::sleep_for(delay_);  // the link's latency, not a synchronisation
      if (send(to, buffer, static_cast<size_t>(n), MSG_NOSIGNAL) != n) break;
    }
    shutdown(to, SHUT_WR);
  }

  int upstream_port_;
  std::chrono::milliseconds delay_;
  int listen_fd_ = -1;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  std::mutex mu_;
  std::vector<int> fds_;
  std::vector<std::thread> pumps_;  // added by the accept thread only, joined after it
  std::thread accept_thread_;
};

// A TLS connection over a link with a 1.6 s round trip (a satellite link, a congested LTE one)
// takes longer than a second to set up. gRPC abandons a connection attempt after its "minimum
// reconnect backoff" (GRPC_ARG_MIN_RECONNECT_BACKOFF_MS is also its minimum connect timeout);
// the client once set that to 100 ms, for quick reconnection, and never connected over such a
// link (nor under ThreadSanitizer, where the handshake is that slow).
TEST_F(SecurityTest, ATlsClientConnectsOverALinkWithALongRoundTrip) {
  ASSERT_FALSE(HasFailure());
  Result<std::unique_ptr<Server>> server = Server::Start(SecureConfig(*pki_));
  ASSERT_TRUE(server.ok()) << server.error().message;
  SlowLink link((*server)->port(), std::chrono::milliseconds(800));
  client::ClientOptions options = TlsClient(*pki_, link.port());
  options.address = "127.0.0.1:" + std::to_string(link.port());
  options.timeout = std::chrono::seconds(30);
  client::Client slow(options);
  v1::GetStatusResponse status;
  const auto start = std::chrono::steady_clock::now();
  const grpc::Status got = slow.GetStatus(&status);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_TRUE(got.ok()) << got.error_message() << " after " << seconds << " s";
  std::cout << "[ figures ] GetStatus over TLS with a 1.6 s round trip: " << seconds << " s\n";
}

TEST(ListenRule, NonLoopbackNeedsAuthenticationOrAnExplicitInsecureFlag) {
  EXPECT_TRUE(IsLoopbackListen("127.0.0.1:50051"));
  EXPECT_TRUE(IsLoopbackListen("127.4.5.6:1"));
  EXPECT_TRUE(IsLoopbackListen("localhost:50051"));
  EXPECT_TRUE(IsLoopbackListen("[::1]:50051"));
  EXPECT_FALSE(IsLoopbackListen("0.0.0.0:50051"));
  EXPECT_FALSE(IsLoopbackListen("[::]:50051"));
  EXPECT_FALSE(IsLoopbackListen("192.168.1.2:50051"));
  EXPECT_FALSE(IsLoopbackListen("drone.local:50051"));

  v1::ServerConfig open;
  open.set_listen("0.0.0.0:0");
  const std::string problems = ::testing::PrintToString(ValidateServerConfig(open));
  EXPECT_THAT(problems, HasSubstr("not a loopback address"));
  EXPECT_THAT(problems, HasSubstr("--allow-insecure"));
  Result<std::unique_ptr<Server>> refused = Server::Start(open);
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused.error().message, HasSubstr("listen"));

  open.set_allow_insecure(true);
  EXPECT_TRUE(ValidateServerConfig(open).empty());

  v1::ServerConfig token_in_clear;
  token_in_clear.set_listen("0.0.0.0:0");
  token_in_clear.mutable_auth()->set_token_file("/etc/stevi/token");
  EXPECT_THAT(::testing::PrintToString(ValidateServerConfig(token_in_clear)),
              HasSubstr("a bearer token needs TLS"));
  v1::ServerConfig names_without_ca;
  names_without_ca.mutable_auth()->add_allowed_client_names("autopilot");
  EXPECT_THAT(::testing::PrintToString(ValidateServerConfig(names_without_ca)),
              HasSubstr("needs tls.client_ca_file"));
}

TEST_F(SecurityTest, BadCredentialFilesAreNamedBeforeAnythingOpens) {
  v1::ServerConfig missing = SecureConfig(*pki_);
  missing.mutable_tls()->set_cert_file(pki_->dir + "/nope.pem");
  Result<std::unique_ptr<Server>> a = Server::Start(missing);
  ASSERT_FALSE(a.ok());
  EXPECT_THAT(a.error().message, HasSubstr("tls.cert_file"));

  v1::ServerConfig short_token = SecureConfig(*pki_);
  std::ofstream(pki_->dir + "/short") << "abc\n";
  short_token.mutable_auth()->set_token_file(pki_->dir + "/short");
  Result<std::unique_ptr<Server>> b = Server::Start(short_token);
  ASSERT_FALSE(b.ok());
  EXPECT_THAT(b.error().message, HasSubstr("at least 16 characters"));
}

TEST(ConstantTimeEquals, ComparesWholeStrings) {
  EXPECT_TRUE(ConstantTimeEquals("", ""));
  EXPECT_TRUE(ConstantTimeEquals("secret-token", "secret-token"));
  EXPECT_FALSE(ConstantTimeEquals("secret-token", "secret-tokem"));
  EXPECT_FALSE(ConstantTimeEquals("secret", "secret-token"));
  EXPECT_FALSE(ConstantTimeEquals("secret-token", "secret"));
  EXPECT_FALSE(ConstantTimeEquals("", "x"));
}

}  // namespace
}  // namespace stevi::server
