#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include "net/inbound.hpp"
#include "net/listener.hpp"
#include "net/ws_connection.hpp"

namespace tactile {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;

namespace {

const char* content_type(const std::filesystem::path& p) {
  const std::string ext = p.extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".json") return "application/json";
  if (ext == ".png") return "image/png";
  if (ext == ".svg") return "image/svg+xml";
  if (ext == ".map") return "application/json";
  return "application/octet-stream";
}

// ---- HTTP: static files, or the upgrade to a WebSocket -------------------------------------

class HttpConnection : public std::enable_shared_from_this<HttpConnection> {
 public:
  HttpConnection(std::shared_ptr<Host> host, uint16_t port, tcp::socket socket)
      : host_(std::move(host)), port_(port), stream_(std::move(socket)) {}

  void start() {
    parser_.emplace();
    parser_->header_limit(16 * 1024);
    parser_->body_limit(16 * 1024);
    stream_.expires_after(std::chrono::seconds(10));
    http::async_read(stream_, buffer_, *parser_, [self = shared_from_this()](beast::error_code ec, size_t) {
      if (ec) return;  // closed, timed out or malformed: nothing to answer
      self->on_request(self->parser_->release());
    });
  }

 private:
  void on_request(http::request<http::string_body> req) {
    if (websocket::is_upgrade(req)) {
      const std::string origin(req[http::field::origin]);
      if (!origin.empty() && !origin_allowed(origin, port_, host_->options().allowed_origins))
        return respond(req, http::status::forbidden, "Origin '" + origin + "' is not allowed to connect\n");
      beast::error_code ec;
      const asio::ip::address peer = stream_.socket().remote_endpoint(ec).address();
      if (ec) return;  // gone already
      if (const Admission a = host_->admit(peer.to_string()); !a.admit) return refuse_upgrade(std::move(req), a.reason);
      auto connection =
          std::make_shared<WsConnection>(host_, stream_.release_socket(), peer.is_loopback(), peer.to_string());
      connection->start(std::move(req));
      return;
    }
    // Files and recordings only to pages that name this server: a page of
    // another site whose name was made to resolve here (DNS rebinding) sends
    // its own name as Host. (An upgrade is guarded by its Origin and token.)
    const std::string host(req[http::field::host]);
    if (!host_allowed(host, host_->options().bind, host_->options().allowed_origins))
      return respond(req, http::status::misdirected_request,
                     "Host '" + utf8_text(host) +
                         "' is not a name of this server: loopback names, the bound "
                         "address, or a host of --allow-origin\n");
    if (req.method() != http::verb::get && req.method() != http::verb::head)
      return respond(req, http::status::method_not_allowed, "only GET and HEAD\n");
    const std::string full(req.target());
    if (full.starts_with("/recordings/")) return serve_recording(req, full.substr(12, full.find('?') - 12));
    if (host_->options().static_dir.empty())
      return respond(req, http::status::not_found, "this server serves no files (no static folder set)\n");
    std::string target(req.target().substr(0, req.target().find('?')));
    if (target.empty() || target[0] != '/' || target.find("..") != std::string::npos)
      return respond(req, http::status::bad_request, "bad path\n");
    if (target.back() == '/') target += "index.html";
    const std::filesystem::path path = std::filesystem::path(host_->options().static_dir) / target.substr(1);
    std::ifstream in(path, std::ios::binary);
    if (!in || std::filesystem::is_directory(path)) return respond(req, http::status::not_found, "not found\n");
    std::string body((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    respond(req, http::status::ok, std::move(body), content_type(path));
  }

  // A refused upgrade is completed and closed at once, so that the client
  // (a browser too, which sees no HTTP status) reads why: close code 1013
  // (try again later) and the reason. The socket goes within a second.
  void refuse_upgrade(http::request<http::string_body> req, const std::string& reason) {
    auto ws = std::make_shared<websocket::stream<beast::tcp_stream>>(stream_.release_socket());
    websocket::stream_base::timeout t = websocket::stream_base::timeout::suggested(beast::role_type::server);
    t.handshake_timeout = std::chrono::seconds(1);
    ws->set_option(t);
    ws->async_accept(req, [ws, why = WsConnection::try_again_later(reason)](beast::error_code ec) {
      if (ec) return;
      ws->async_close(why, [ws](beast::error_code) {});
    });
  }

  // The recordings folder: "/recordings/" lists its MCAP files (JSON: name,
  // bytes), "/recordings/NAME" downloads one (Foxglove opens it).
  void serve_recording(const http::request<http::string_body>& req, const std::string& name) {
    const std::string& dir = host_->options().recordings_dir;
    if (dir.empty()) return respond(req, http::status::not_found, "this server keeps no recordings (--recordings)\n");
    // A recording holds a whole session: off loopback, only with the token (?token=...), as every role needs.
    beast::error_code peer_ec;
    const bool loopback = stream_.socket().remote_endpoint(peer_ec).address().is_loopback() && !peer_ec;
    if (!loopback) {
      const std::string target(req.target());
      const size_t q = target.find("token=");
      const std::string given = q == std::string::npos ? "" : target.substr(q + 6, target.find('&', q) - q - 6);
      if (host_->options().token.empty() || given != host_->options().token)
        return respond(req, http::status::unauthorized, "recordings need the token off loopback (?token=...)\n");
    }
    std::error_code ec;
    if (name.empty()) {
      std::vector<std::pair<std::string, uintmax_t>> files;
      for (const auto& entry : std::filesystem::directory_iterator(dir, ec))
        if (entry.is_regular_file() && entry.path().extension() == ".mcap")
          files.emplace_back(entry.path().filename().string(), entry.file_size(ec));
      std::sort(files.begin(), files.end());
      std::string body = "[";
      for (const auto& [n, size] : files)
        body +=
            std::string(body.size() > 1 ? "," : "") + "{\"name\":\"" + n + "\",\"bytes\":" + std::to_string(size) + "}";
      return respond(req, http::status::ok, body + "]\n", "application/json");
    }
    const bool plain = name[0] != '.' && std::all_of(name.begin(), name.end(), [](char ch) {
                         return std::isalnum(static_cast<unsigned char>(ch)) || ch == '.' || ch == '_' || ch == '-';
                       });
    if (!plain || !name.ends_with(".mcap")) return respond(req, http::status::bad_request, "not a recording's name\n");
    std::ifstream in(std::filesystem::path(dir) / name, std::ios::binary);
    if (!in) return respond(req, http::status::not_found, "no recording '" + name + "'\n");
    std::string body((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    respond(req, http::status::ok, std::move(body), "application/octet-stream");
  }

  void respond(const http::request<http::string_body>& req, http::status status, std::string body,
               const char* type = "text/plain; charset=utf-8") {
    auto res = std::make_shared<http::response<http::string_body>>(status, req.version());
    res->set(http::field::server, host_->options().server_name);
    res->set(http::field::content_type, type);
    res->set(http::field::cache_control, "no-cache");
    res->keep_alive(false);
    if (req.method() != http::verb::head) res->body() = std::move(body);
    res->prepare_payload();
    http::async_write(stream_, *res, [self = shared_from_this(), res](beast::error_code, size_t) {
      beast::error_code ignored;
      self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    });
  }

  std::shared_ptr<Host> host_;
  uint16_t port_;  // the listener's, for the page's own Origin
  beast::tcp_stream stream_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
};

}  // namespace

void serve_http(std::shared_ptr<Host> host, uint16_t port, tcp::socket socket) {
  std::make_shared<HttpConnection>(std::move(host), port, std::move(socket))->start();
}

}  // namespace tactile
