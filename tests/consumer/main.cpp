// Builds against the installed avsplat and exercises a call into the library.
#include <avsplat/core/gaussians.h>
#include <avsplat/io/ply.h>

#include <cstdio>

int main(int argc, char** argv) {
    if (argc < 2) return 2;
    avsplat::GaussianCloud cloud(3, 1);
    cloud.means[4] = 2.5f;
    avsplat::write_ply(argv[1], cloud);
    const avsplat::GaussianCloud back = avsplat::read_ply(argv[1]);
    if (back.size() != 3 || back.sh_degree != 1 || back.means[4] != 2.5f) {
        std::fprintf(stderr, "consumer: round trip through the installed library failed\n");
        return 1;
    }
    std::printf("consumer: ok (%zu Gaussians)\n", back.size());
    return 0;
}
