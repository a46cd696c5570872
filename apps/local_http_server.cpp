#include "local_http_server.h"

#include "avsplat/core/error.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace avsplat::cli {
namespace {

// Sends all of `data`; false when the peer went away or stalled (the send timeout).
bool send_all(int fd, const char* data, std::size_t n) {
    while (n > 0) {
        const ssize_t sent = ::send(fd, data, n, MSG_NOSIGNAL);
        if (sent < 0) {
            if (errno == EINTR) continue;
            return false;
        }
        data += sent;
        n -= static_cast<std::size_t>(sent);
    }
    return true;
}

void respond(int fd, int status, const char* reason, const std::string& type, const std::string& body,
             bool with_body) {
    std::string head = "HTTP/1.1 " + std::to_string(status) + " " + reason + "\r\nContent-Type: " + type +
                       "\r\nContent-Length: " + std::to_string(body.size()) +
                       "\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n";
    if (send_all(fd, head.data(), head.size()) && with_body) send_all(fd, body.data(), body.size());
}

// Reads the request head (up to the blank line, at most 16 KiB); "" when none came in time.
std::string read_head(int fd) {
    std::string head;
    char buf[4096];
    while (head.find("\r\n\r\n") == std::string::npos && head.size() < 16384) {
        const ssize_t got = ::recv(fd, buf, sizeof buf, 0);
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) return head.find("\r\n") == std::string::npos ? std::string() : head;
        head.append(buf, static_cast<std::size_t>(got));
    }
    return head;
}

void handle(int fd, const std::map<std::string, HttpResource>& resources) {
    const std::string head = read_head(fd);
    const std::size_t line_end = head.find("\r\n");
    if (line_end == std::string::npos) return;
    const std::string line = head.substr(0, line_end);
    const std::size_t a = line.find(' ');
    const std::size_t b = a == std::string::npos ? std::string::npos : line.find(' ', a + 1);
    if (b == std::string::npos) {
        respond(fd, 400, "Bad Request", "text/plain", "bad request\n", true);
        return;
    }
    const std::string method = line.substr(0, a);
    std::string path = line.substr(a + 1, b - a - 1);
    path = path.substr(0, path.find('?'));
    if (method != "GET" && method != "HEAD") {
        respond(fd, 405, "Method Not Allowed", "text/plain", "only GET and HEAD\n", true);
        return;
    }
    const auto it = resources.find(path);
    if (it == resources.end()) {
        respond(fd, 404, "Not Found", "text/plain", "not found\n", method == "GET");
        return;
    }
    respond(fd, 200, "OK", it->second.content_type, it->second.body, method == "GET");
}

}  // namespace

LocalHttpServer::LocalHttpServer(int port) {
    if (port < 0 || port > 65535) throw IOError("--port: " + std::to_string(port) + " is not a port (0..65535)");
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0) throw IOError(std::string("cannot open a socket: ") + std::strerror(errno));
    const int on = 1;
    ::setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &on, sizeof on);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);  // never reachable from another machine
    addr.sin_port = htons(static_cast<std::uint16_t>(port));
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(fd_, 16) != 0) {
        const int err = errno;
        ::close(fd_);
        throw IOError("cannot listen on 127.0.0.1:" + std::to_string(port) + ": " + std::strerror(err));
    }
    socklen_t len = sizeof addr;
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&addr), &len);
    port_ = ntohs(addr.sin_port);
}

LocalHttpServer::~LocalHttpServer() {
    if (fd_ >= 0) ::close(fd_);
}

void LocalHttpServer::serve(const std::map<std::string, HttpResource>& resources, const std::function<void()>& idle) {
    for (;;) {
        idle();
        pollfd p{fd_, POLLIN, 0};
        const int ready = ::poll(&p, 1, 200);
        if (ready < 0 && errno != EINTR) throw IOError(std::string("serving: poll failed: ") + std::strerror(errno));
        if (ready <= 0) continue;
        const int client = ::accept4(fd_, nullptr, nullptr, SOCK_CLOEXEC);
        if (client < 0) continue;  // the peer gave up, or a signal: back to the check
        // A stalled browser must not hold the server (and Ctrl-C) for long.
        timeval timeout{5, 0};
        ::setsockopt(client, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
        ::setsockopt(client, SOL_SOCKET, SO_SNDTIMEO, &timeout, sizeof timeout);
        handle(client, resources);
        ::shutdown(client, SHUT_WR);
        ::close(client);
    }
}

}  // namespace avsplat::cli
