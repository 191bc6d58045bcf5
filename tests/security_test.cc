// Security: bearer tokens (UNAUTHENTICATED without a valid one; a session
// is invisible to other tokens; the token file is reread when it changes),
// the safe default (no public address without auth), and TLS with optional
// client certificates (certificates made by openssl at test time).
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "server/client_id.h"
#include "server/server.h"
#include "swarf/v1/swarf.grpc.pb.h"

namespace swarf::server {
namespace {

namespace pb = ::swarf::v1;
namespace fs = std::filesystem;

class SecurityTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("swarf-sec-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    server_.reset();
    fs::remove_all(dir_);
  }

  void WriteTokens(const std::string& text) {
    std::ofstream(dir_ / "tokens") << text;
  }

  void Start(ServerOptions opt) {
    opt.listen = "127.0.0.1:0";
    auto s = SwarfServer::Start(opt);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
  }

  std::unique_ptr<pb::Swarf::Stub> Stub(
      std::shared_ptr<grpc::ChannelCredentials> creds =
          grpc::InsecureChannelCredentials()) {
    grpc::ChannelArguments args;
    // The test certificate is for "localhost".
    args.SetSslTargetNameOverride("localhost");
    return pb::Swarf::NewStub(grpc::CreateCustomChannel(
        "127.0.0.1:" + std::to_string(server_->port()), creds, args));
  }

  static std::unique_ptr<grpc::ClientContext> Ctx(const std::string& token,
                                                  const std::string& id = "") {
    auto c = std::make_unique<grpc::ClientContext>();
    if (!token.empty()) c->AddMetadata("authorization", "Bearer " + token);
    if (!id.empty()) c->AddMetadata("x-swarf-session", id);
    c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
    return c;
  }

  static pb::CreateSessionRequest Request(const std::string& id) {
    pb::CreateSessionRequest r;
    r.set_session_id(id);
    r.mutable_stock()->set_x1(10);
    r.mutable_stock()->set_y1(10);
    r.set_nx(10);
    r.set_ny(10);
    pb::Tool* t = r.add_tools();
    t->set_id(1);
    t->mutable_ball()->set_radius(1);
    return r;
  }

  grpc::StatusCode Create(pb::Swarf::Stub* stub, const std::string& token,
                          const std::string& id) {
    pb::Session s;
    return stub->CreateSession(Ctx(token).get(), Request(id), &s).error_code();
  }
  grpc::StatusCode Get(pb::Swarf::Stub* stub, const std::string& token,
                       const std::string& id) {
    pb::GetSessionRequest r;
    r.set_session_id(id);
    pb::Session s;
    return stub->GetSession(Ctx(token).get(), r, &s).error_code();
  }
  // A Simulate stream's status after one batch.
  grpc::StatusCode Stream(pb::Swarf::Stub* stub, const std::string& token,
                          const std::string& id, bool* acked) {
    auto ctx = Ctx(token, id);
    auto s = stub->Simulate(ctx.get());
    pb::SimulateRequest req;
    req.mutable_moves()->set_seq(1);
    req.mutable_moves()->set_tool_id(1);
    for (double v : {2.0, 2.0, -0.5, 8.0, 2.0, -0.5}) {
      req.mutable_moves()->add_xyz(v);
    }
    s->Write(req);
    s->WritesDone();
    pb::SimulateResponse resp;
    *acked = false;
    while (s->Read(&resp)) *acked |= resp.has_ack();
    return s->Finish().error_code();
  }

  // A Simulate stream held open, and whether it is up (a stats request
  // was answered).
  struct Open {
    std::unique_ptr<grpc::ClientContext> ctx;
    std::unique_ptr<grpc::ClientReaderWriter<pb::SimulateRequest,
                                             pb::SimulateResponse>> stream;
  };
  static std::pair<Open, bool> OpenStream(
      pb::Swarf::Stub* stub, std::unique_ptr<grpc::ClientContext> ctx) {
    Open o;
    o.ctx = std::move(ctx);
    o.stream = stub->Simulate(o.ctx.get());
    pb::SimulateRequest req;
    req.mutable_stats()->set_request_id(1);
    o.stream->Write(req);
    pb::SimulateResponse resp;
    const bool up = o.stream->Read(&resp);
    return std::pair{std::move(o), up};
  }
  static void Close(Open* o) {
    o->stream->WritesDone();
    o->stream->Finish().IgnoreError();
  }

  fs::path dir_;
  std::unique_ptr<SwarfServer> server_;
};

TEST_F(SecurityTest, TokensAuthenticateAndSessionsBelongToTheirCreator) {
  WriteTokens("# team tokens\nalpha-token\n\n  beta-token  \n");
  ServerOptions opt;
  opt.auth_tokens_file = (dir_ / "tokens").string();
  ASSERT_NO_FATAL_FAILURE(Start(opt));
  auto stub = Stub();
  using C = grpc::StatusCode;
  // No token, a wrong one: UNAUTHENTICATED, whatever the call.
  EXPECT_EQ(Create(stub.get(), "", "s1"), C::UNAUTHENTICATED);
  EXPECT_EQ(Create(stub.get(), "gamma-token", "s1"), C::UNAUTHENTICATED);
  EXPECT_EQ(Get(stub.get(), "", "s1"), C::UNAUTHENTICATED);
  bool acked;
  EXPECT_EQ(Stream(stub.get(), "", "s1", &acked), C::UNAUTHENTICATED);
  {
    pb::ListSessionsResponse list;
    EXPECT_EQ(stub->ListSessions(Ctx("").get(), {}, &list).error_code(),
              C::UNAUTHENTICATED);
  }
  // alpha's session: alpha uses it; to beta it does not exist.
  ASSERT_EQ(Create(stub.get(), "alpha-token", "s1"), C::OK);
  EXPECT_EQ(Get(stub.get(), "alpha-token", "s1"), C::OK);
  EXPECT_EQ(Stream(stub.get(), "alpha-token", "s1", &acked), C::OK);
  EXPECT_TRUE(acked);
  EXPECT_EQ(Get(stub.get(), "beta-token", "s1"), C::NOT_FOUND);
  EXPECT_EQ(Get(stub.get(), "beta-token", "no-such"), C::NOT_FOUND);
  EXPECT_EQ(Stream(stub.get(), "beta-token", "s1", &acked), C::NOT_FOUND);
  EXPECT_FALSE(acked);
  {
    pb::ListSessionsResponse list;
    ASSERT_TRUE(stub->ListSessions(Ctx("beta-token").get(), {}, &list).ok());
    EXPECT_EQ(list.sessions_size(), 0);
    ASSERT_TRUE(stub->ListSessions(Ctx("alpha-token").get(), {}, &list).ok());
    EXPECT_EQ(list.sessions_size(), 1);
  }
  {
    pb::DeleteSessionRequest del;
    del.set_session_id("s1");
    pb::DeleteSessionResponse r;
    EXPECT_EQ(stub->DeleteSession(Ctx("beta-token").get(), del, &r).error_code(),
              C::NOT_FOUND);
    EXPECT_EQ(Get(stub.get(), "alpha-token", "s1"), C::OK);
  }
  // The file changes: gamma is in, beta is out, without a restart.
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  WriteTokens("alpha-token\ngamma-token\n");
  bool switched = false;
  for (int i = 0; i < 40 && !switched; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    switched = Create(stub.get(), "gamma-token", "s2") == C::OK;
  }
  EXPECT_TRUE(switched) << "the token file was not reread";
  EXPECT_EQ(Get(stub.get(), "beta-token", "s1"), C::UNAUTHENTICATED);
  EXPECT_EQ(Get(stub.get(), "alpha-token", "s1"), C::OK);
}

TEST_F(SecurityTest, NoPublicAddressWithoutAuthUnlessAskedFor) {
  ServerOptions opt;
  opt.listen = "0.0.0.0:0";
  auto refused = SwarfServer::Start(opt);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(refused.status().message().find("--insecure_public"),
            std::string::npos);
  opt.insecure_public = true;
  EXPECT_TRUE(SwarfServer::Start(opt).ok());
  opt.insecure_public = false;
  WriteTokens("t\n");
  opt.auth_tokens_file = (dir_ / "tokens").string();
  EXPECT_TRUE(SwarfServer::Start(opt).ok());
  EXPECT_TRUE(IsLoopback("127.0.0.1:50051"));
  EXPECT_TRUE(IsLoopback("localhost:1"));
  EXPECT_TRUE(IsLoopback("[::1]:1"));
  EXPECT_FALSE(IsLoopback("0.0.0.0:1"));
  EXPECT_FALSE(IsLoopback("[::]:1"));
  EXPECT_FALSE(IsLoopback("10.1.2.3:1"));
}

TEST_F(SecurityTest, StreamsPerClientAreLimited) {
  WriteTokens("alpha-token\nbeta-token\n");
  ServerOptions opt;
  opt.auth_tokens_file = (dir_ / "tokens").string();
  opt.limits.max_streams_per_client = 2;
  ASSERT_NO_FATAL_FAILURE(Start(opt));
  auto stub = Stub();
  ASSERT_EQ(Create(stub.get(), "alpha-token", "a"), grpc::StatusCode::OK);
  ASSERT_EQ(Create(stub.get(), "beta-token", "b"), grpc::StatusCode::OK);
  // Two streams held open by alpha: a third is refused, beta's is not.
  auto open = [&](const std::string& token, const std::string& id) {
    return OpenStream(stub.get(), Ctx(token, id));
  };
  auto [s1, up1] = open("alpha-token", "a");
  auto [s2, up2] = open("alpha-token", "a");
  EXPECT_TRUE(up1 && up2);
  auto [s3, up3] = open("alpha-token", "a");
  EXPECT_FALSE(up3);
  s3.stream->WritesDone();
  const grpc::Status refused = s3.stream->Finish();
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(refused.error_message().find("streams"), std::string::npos);
  auto [s4, up4] = open("beta-token", "b");
  EXPECT_TRUE(up4);
  // Closing one makes room again.
  s1.stream->WritesDone();
  EXPECT_TRUE(s1.stream->Finish().ok());
  bool up5 = false;
  for (int i = 0; i < 20 && !up5; ++i) {  // the release is asynchronous
    auto [s5, up] = open("alpha-token", "a");
    up5 = up;
    s5.stream->WritesDone();
    s5.stream->Finish();
    if (!up5) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_TRUE(up5);
  for (Open* o : {&s2, &s4}) {
    o->stream->WritesDone();
    o->stream->Finish();
  }
}

// Behind a balancer every stream comes from the balancer's address. When it
// is trusted, the x-real-ip it sets names the client; from anyone else the
// header is ignored, so a client cannot choose whose streams it uses.
TEST_F(SecurityTest, StreamsBehindATrustedBalancerCountPerRealClient) {
  ServerOptions opt;
  opt.limits.max_streams_per_client = 1;
  opt.trusted_proxies = "10.1.0.0/16, 127.0.0.0/8";
  ASSERT_NO_FATAL_FAILURE(Start(opt));
  auto stub = Stub();
  ASSERT_EQ(Create(stub.get(), "", "a"), grpc::StatusCode::OK);
  auto open = [&](const std::string& real_ip) {
    auto ctx = Ctx("", "a");
    if (!real_ip.empty()) ctx->AddMetadata("x-real-ip", real_ip);
    return OpenStream(stub.get(), std::move(ctx));
  };
  auto [c1, up1] = open("192.0.2.1");
  auto [c1again, up1again] = open("192.0.2.1");
  auto [c2, up2] = open("2001:db8::7");
  EXPECT_TRUE(up1);
  EXPECT_FALSE(up1again) << "the same client twice";
  EXPECT_TRUE(up2) << "another client behind the same balancer";
  // Not an address: the balancer's own.
  auto [junk, up_junk] = open("not-an-ip");
  auto [direct, up_direct] = open("");
  EXPECT_TRUE(up_junk);
  EXPECT_FALSE(up_direct);
  for (Open* o : {&c1, &c1again, &c2, &junk, &direct}) Close(o);

  // Untrusted (only 10.1.0.0/16): every stream is 127.0.0.1's.
  server_.reset();
  opt.trusted_proxies = "10.1.0.0/16";
  ASSERT_NO_FATAL_FAILURE(Start(opt));
  stub = Stub();
  ASSERT_EQ(Create(stub.get(), "", "a"), grpc::StatusCode::OK);
  auto [d1, ok1] = open("192.0.2.1");
  auto [d2, ok2] = open("192.0.2.2");
  EXPECT_TRUE(ok1);
  EXPECT_FALSE(ok2) << "x-real-ip from an untrusted peer was believed";
  for (Open* o : {&d1, &d2}) Close(o);
}

TEST(ClientIdTest, TrustedProxiesParseAndMatch) {
  auto t = ProxyTrust::Parse("127.0.0.1, 10.0.0.0/8,fd00::/8,192.168.4.0/23");
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_TRUE(t->Trusts("127.0.0.1"));
  EXPECT_FALSE(t->Trusts("127.0.0.2"));
  EXPECT_TRUE(t->Trusts("10.255.3.4"));
  EXPECT_FALSE(t->Trusts("11.0.0.1"));
  EXPECT_TRUE(t->Trusts("192.168.5.200"));  // /23: .4.0 - .5.255
  EXPECT_FALSE(t->Trusts("192.168.6.1"));
  EXPECT_TRUE(t->Trusts("fd12::1"));
  EXPECT_FALSE(t->Trusts("fe80::1"));
  EXPECT_FALSE(t->Trusts("::ffff:10.0.0.1"));  // another family
  EXPECT_FALSE(t->Trusts("garbage"));
  EXPECT_TRUE(ProxyTrust::Parse("")->empty());
  EXPECT_TRUE(ProxyTrust::Parse("0.0.0.0/0")->Trusts("8.8.8.8"));
  for (const char* bad : {"10.0.0.0/33", "fd00::/129", "10.0.0/8", "host",
                          "10.0.0.0/", "10.0.0.0/-1", "10.0.0.0/8x"}) {
    const auto p = ProxyTrust::Parse(bad);
    EXPECT_EQ(p.status().code(), absl::StatusCode::kInvalidArgument) << bad;
    EXPECT_NE(p.status().message().find(bad), std::string::npos) << bad;
  }
  // swarfd refuses to start with a bad list.
  ServerOptions opt;
  opt.listen = "127.0.0.1:0";
  opt.trusted_proxies = "10.0.0.0/33";
  EXPECT_EQ(SwarfServer::Start(opt).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(ClientIdTest, ClientKeys) {
  EXPECT_EQ(PeerAddress("ipv4:10.1.2.3:5000"), "10.1.2.3");
  EXPECT_EQ(PeerAddress("ipv6:[::1]:5000"), "::1");
  EXPECT_EQ(PeerAddress("unix:/tmp/s"), "unix:/tmp/s");
  const ProxyTrust trust = *ProxyTrust::Parse("10.0.0.5");
  const std::string ip = "192.0.2.9", junk = "x";
  EXPECT_EQ(ClientKey("principal", "ipv4:10.0.0.5:1", &ip, trust),
            "principal");
  EXPECT_EQ(ClientKey("", "ipv4:10.0.0.5:1", &ip, trust), ip);
  EXPECT_EQ(ClientKey("", "ipv4:10.0.0.6:1", &ip, trust), "10.0.0.6");
  EXPECT_EQ(ClientKey("", "ipv4:10.0.0.5:1", &junk, trust), "10.0.0.5");
  EXPECT_EQ(ClientKey("", "ipv4:10.0.0.5:1", nullptr, trust), "10.0.0.5");
}

// A CA, a server certificate for localhost and a client certificate.
bool MakeCertificates(const fs::path& d) {
  const std::string q = "cd '" + d.string() + "' && ";
  const std::string cmds[] = {
      "openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj /CN=swarf-ca "
      "-keyout ca.key -out ca.pem",
      "openssl req -newkey rsa:2048 -nodes -subj /CN=localhost -keyout "
      "server.key -out server.csr",
      "printf 'subjectAltName=DNS:localhost,IP:127.0.0.1' > san.ext && "
      "openssl x509 -req -in server.csr -CA ca.pem -CAkey ca.key "
      "-CAcreateserial -days 2 -extfile san.ext -out server.pem",
      "openssl req -newkey rsa:2048 -nodes -subj /CN=client -keyout "
      "client.key -out client.csr",
      "openssl x509 -req -in client.csr -CA ca.pem -CAkey ca.key "
      "-CAcreateserial -days 2 -out client.pem"};
  for (const std::string& c : cmds) {
    if (std::system((q + c + " >/dev/null 2>&1").c_str()) != 0) return false;
  }
  return true;
}

std::string Read(const fs::path& p) {
  std::ifstream in(p);
  return std::string((std::istreambuf_iterator<char>(in)),
                     std::istreambuf_iterator<char>());
}

TEST_F(SecurityTest, TlsAndClientCertificates) {
  ASSERT_TRUE(MakeCertificates(dir_)) << "openssl failed (install-deps has it)";
  ServerOptions opt;
  opt.tls_cert = (dir_ / "server.pem").string();
  opt.tls_key = (dir_ / "server.key").string();
  ASSERT_NO_FATAL_FAILURE(Start(opt));
  grpc::SslCredentialsOptions ssl;
  ssl.pem_root_certs = Read(dir_ / "ca.pem");
  EXPECT_EQ(Create(Stub(grpc::SslCredentials(ssl)).get(), "", "tls1"),
            grpc::StatusCode::OK);
  // Plaintext to a TLS port fails.
  EXPECT_NE(Create(Stub().get(), "", "plain"), grpc::StatusCode::OK);

  // Client certificates required: without one no call gets through.
  server_.reset();
  opt.tls_client_ca = (dir_ / "ca.pem").string();
  ASSERT_NO_FATAL_FAILURE(Start(opt));
  EXPECT_NE(Create(Stub(grpc::SslCredentials(ssl)).get(), "", "nocert"),
            grpc::StatusCode::OK);
  ssl.pem_cert_chain = Read(dir_ / "client.pem");
  ssl.pem_private_key = Read(dir_ / "client.key");
  EXPECT_EQ(Create(Stub(grpc::SslCredentials(ssl)).get(), "", "withcert"),
            grpc::StatusCode::OK);
}

}  // namespace
}  // namespace swarf::server
