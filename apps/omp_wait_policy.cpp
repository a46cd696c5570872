// The tool's OpenMP threads sleep when they have no work (OMP_WAIT_POLICY=PASSIVE) unless the
// user chose a policy. libgomp's default spins a waiting thread (GOMP_SPINCOUNT 300000) before it
// sleeps, which takes CPU from other processes on a shared machine between the tool's parallel
// regions; with PASSIVE it sleeps at once.
//
// libgomp reads OMP_WAIT_POLICY once, in its initialiser, which runs before main() and before the
// executable's constructors. Setting the variable earlier does not work either: libc's own
// initialiser, which runs after the executable's .preinit_array, resets the environment to the
// one the process started with. So the executable defines getenv (the executable's symbols come
// first in symbol lookup, so libgomp's call resolves here): the usual lookup, except that an
// unset OMP_WAIT_POLICY reads as PASSIVE. A constructor then sets the variable for real, so that
// child processes (avsplat eval runs Python) inherit the choice.
// `OMP_DISPLAY_ENV=VERBOSE avsplat --help` shows what libgomp read (GOMP_SPINCOUNT = '0').
#include <cstring>

#include <stdlib.h>
#include <unistd.h>

namespace {

constexpr char kName[] = "OMP_WAIT_POLICY";

}  // namespace

extern "C" char* getenv(const char* name) noexcept {
    const std::size_t n = std::strlen(name);
    if (environ != nullptr)
        for (char** e = environ; *e != nullptr; ++e)
            if (std::strncmp(*e, name, n) == 0 && (*e)[n] == '=') return *e + n + 1;
    static char passive[] = "PASSIVE";
    return std::strcmp(name, kName) == 0 ? passive : nullptr;
}

__attribute__((constructor)) static void default_to_passive_wait() { setenv(kName, "PASSIVE", /*overwrite=*/0); }
