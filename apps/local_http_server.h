// A minimal HTTP/1.1 server for `avsplat view`: fixed resources (path -> bytes) served to GET
// and HEAD on 127.0.0.1 only, one connection at a time, each closed after its response.
#pragma once

#include <functional>
#include <map>
#include <string>

namespace avsplat::cli {

struct HttpResource {
    std::string content_type;
    std::string body;
};

class LocalHttpServer {
public:
    /// Listens on 127.0.0.1:port (0: an ephemeral port the system picks). Throws IOError when the
    /// port cannot be bound (in use, or not permitted).
    explicit LocalHttpServer(int port);
    ~LocalHttpServer();
    LocalHttpServer(const LocalHttpServer&) = delete;
    LocalHttpServer& operator=(const LocalHttpServer&) = delete;

    /// The port listened on.
    int port() const { return port_; }

    /// Serves `resources` until `idle` throws (it is called at least every 200 ms, between
    /// connections, to check for Ctrl-C and the like). Unknown paths get 404, other methods 405.
    void serve(const std::map<std::string, HttpResource>& resources, const std::function<void()>& idle);

private:
    int fd_ = -1;
    int port_ = 0;
};

}  // namespace avsplat::cli
