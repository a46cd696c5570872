# Sourced by the scripts that need Debian packages: ensure_packages P... installs the ones that
# are missing (as root, or with sudo), and does nothing when all are there.
ensure_packages() {
  local missing=() p sudo=""
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  ((${#missing[@]})) || return 0
  echo "installing ${missing[*]}"
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

# The Debian packages of the core library and its C++ tests (no Open3D, apps or Python):
# setup.sh installs them with the rest, gpu_deps.sh carries them to a machine that lacks them.
core_dev_packages=(
  libeigen3-dev libnanoflann-dev catch2 nlohmann-json3-dev zlib1g-dev libpng-dev
  libzip-dev libzstd-dev libwebp-dev
  pkg-config  # finds libzip (its CMake package needs tools libzip-dev does not install)
)
