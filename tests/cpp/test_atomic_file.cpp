#include "avsplat/core/error.h"
#include "avsplat/io/atomic_file.h"
#include "avsplat/io/camera_json.h"

#include <catch2/catch.hpp>

#include <dirent.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

std::string fresh_dir(const std::string& name) {
    const std::string dir = std::string(AVSPLAT_TEST_TMP) + "/atomic_" + name;
    std::string cmd = "rm -rf '" + dir + "' && mkdir -p '" + dir + "'";
    REQUIRE(std::system(cmd.c_str()) == 0);
    return dir;
}

std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

std::vector<std::string> entries(const std::string& dir) {
    std::vector<std::string> names;
    DIR* d = opendir(dir.c_str());
    REQUIRE(d != nullptr);
    while (dirent* e = readdir(d))
        if (std::string(e->d_name) != "." && std::string(e->d_name) != "..") names.push_back(e->d_name);
    closedir(d);
    return names;
}

void write_old(const std::string& path) {
    std::ofstream(path, std::ios::binary) << "old good file";
}

}  // namespace

TEST_CASE("AtomicFile writes the bytes with a new file's permissions", "[io][atomic]") {
    const std::string dir = fresh_dir("plain");
    const std::string path = dir + "/a.bin";
    avsplat::write_file_atomically(path, std::string("hello\0world", 11));
    CHECK(slurp(path) == std::string("hello\0world", 11));
    struct stat st;
    REQUIRE(stat(path.c_str(), &st) == 0);
    const mode_t mask = umask(0);
    umask(mask);
    CHECK((st.st_mode & 0777) == (0666 & ~mask));
    CHECK(entries(dir) == std::vector<std::string>{"a.bin"});
}

TEST_CASE("AtomicFile leaves the destination untouched when the write fails", "[io][atomic]") {
    const std::string dir = fresh_dir("fail");
    const std::string path = dir + "/keep.ply";
    write_old(path);
    SECTION("an exception before commit removes the temporary file") {
        try {
            avsplat::AtomicFile f(path);
            f.write("partial new", 11);
            throw std::runtime_error("writer failed");
        } catch (const std::runtime_error&) {
        }
        CHECK(slurp(path) == "old good file");
        CHECK(entries(dir) == std::vector<std::string>{"keep.ply"});
    }
    SECTION("a file-size limit (RLIMIT_FSIZE) gives IOError, not SIGXFSZ") {
        const pid_t pid = fork();
        REQUIRE(pid >= 0);
        if (pid == 0) {
            signal(SIGXFSZ, SIG_IGN);
            rlimit lim{4096, 4096};
            setrlimit(RLIMIT_FSIZE, &lim);
            try {
                avsplat::AtomicFile f(path);
                std::string chunk(1 << 16, 'x');
                for (int i = 0; i < 16; ++i) f.write(chunk);
                f.commit();
            } catch (const avsplat::IOError& e) {
                const std::string msg = e.what();
                _exit(msg.find(path) != std::string::npos ? 42 : 2);
            }
            _exit(1);
        }
        int status = 0;
        waitpid(pid, &status, 0);
        REQUIRE(WIFEXITED(status));
        CHECK(WEXITSTATUS(status) == 42);
        CHECK(slurp(path) == "old good file");
        CHECK(entries(dir) == std::vector<std::string>{"keep.ply"});
    }
    SECTION("a writer killed with SIGKILL mid-write leaves the old file") {
        int ready[2];
        REQUIRE(pipe(ready) == 0);
        const pid_t pid = fork();
        REQUIRE(pid >= 0);
        if (pid == 0) {
            avsplat::AtomicFile f(path);
            std::string chunk(1 << 20, 'y');
            f.write(chunk);
            (void)!::write(ready[1], "r", 1);
            for (;;) f.write(chunk), usleep(1000);
        }
        char c;
        REQUIRE(read(ready[0], &c, 1) == 1);
        kill(pid, SIGKILL);
        int status = 0;
        waitpid(pid, &status, 0);
        close(ready[0]);
        close(ready[1]);
        CHECK(slurp(path) == "old good file");
    }
}

TEST_CASE("AtomicFile reports full disks, missing folders and FIFOs clearly", "[io][atomic]") {
    try {
        avsplat::write_file_atomically("/dev/full", std::string(1 << 16, 'z'));
        FAIL("/dev/full accepted the write");
    } catch (const avsplat::IOError& e) {
        CHECK(std::string(e.what()).find("/dev/full: write failed: No space left on device") == 0);
    }
    struct stat st;
    REQUIRE(stat("/dev/full", &st) == 0);
    CHECK(S_ISCHR(st.st_mode));  // the device was written in place, not replaced

    const std::string missing = std::string(AVSPLAT_TEST_TMP) + "/no/such/folder/out.json";
    CHECK_THROWS_WITH(avsplat::write_file_atomically(missing, "x"),
                      Catch::StartsWith(missing + ": cannot open for writing (creating a file in"));

    const std::string dir = fresh_dir("fifo");
    const std::string fifo = dir + "/pipe";
    REQUIRE(mkfifo(fifo.c_str(), 0600) == 0);
    // No reader: the open must fail at once instead of blocking forever.
    CHECK_THROWS_WITH(avsplat::write_file_atomically(fifo, "x"),
                      Catch::StartsWith(fifo + ": cannot open for writing"));
    CHECK_THROWS_WITH(avsplat::write_file_atomically(dir, "x"), Catch::Contains("is a directory"));
}

TEST_CASE("AtomicFile replaces a symbolic link's target and keeps the link", "[io][atomic]") {
    const std::string dir = fresh_dir("link");
    write_old(dir + "/real.json");
    REQUIRE(symlink("real.json", (dir + "/link.json").c_str()) == 0);
    avsplat::write_file_atomically(dir + "/link.json", "new");
    struct stat st;
    REQUIRE(lstat((dir + "/link.json").c_str(), &st) == 0);
    CHECK(S_ISLNK(st.st_mode));
    CHECK(slurp(dir + "/real.json") == "new");
}

TEST_CASE("write_cameras_json fails loudly on a full disk", "[io][atomic][camera]") {
    avsplat::Camera cam;
    cam.fx = cam.fy = 100;
    cam.cx = 32;
    cam.cy = 24;
    cam.width = 64;
    cam.height = 48;
    CHECK_THROWS_AS(avsplat::write_camera_json("/dev/full", cam), avsplat::IOError);
}

namespace {

// The PID of a process that has exited and been reaped.
pid_t dead_pid() {
    const pid_t pid = fork();
    if (pid == 0) _exit(0);
    int status = 0;
    waitpid(pid, &status, 0);
    return pid;
}

bool exists(const std::string& path) {
    struct stat st;
    return ::lstat(path.c_str(), &st) == 0;
}

}  // namespace

TEST_CASE("AtomicFile removes the temporary files of killed writers, and only those", "[io][atomic]") {
    const std::string dir = fresh_dir("stale");
    const std::string dest = dir + "/scene.ply";
    // A writer SIGKILLed mid-write: its temporary file carries its PID and its lock is gone.
    const pid_t killed = fork();
    if (killed == 0) {
        avsplat::AtomicFile f(dest);
        f.write("partial");
        ::kill(::getpid(), SIGKILL);
    }
    int status = 0;
    waitpid(killed, &status, 0);
    REQUIRE(WIFSIGNALED(status));
    std::vector<std::string> left = entries(dir);
    REQUIRE(left.size() == 1);
    CHECK(left[0].rfind(".scene.ply.avsplat-" + std::to_string(killed) + "-", 0) == 0);
    // Scratch of a live writer (this process, lock held) and of another name stay.
    avsplat::AtomicFile live(dest);
    const std::string other = dir + "/.other.ply.avsplat-" + std::to_string(dead_pid()) + "-abcdef";
    { std::ofstream(other) << "x"; }
    CHECK_FALSE(exists(dir + "/" + left[0]));  // removed when `live` was made
    avsplat::AtomicFile second(dest);          // does not remove `live`'s file
    live.write("whole");
    live.commit();
    CHECK(slurp(dest) == "whole");
    CHECK(exists(other));
}
