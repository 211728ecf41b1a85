#!/usr/bin/env bash
# Installs every Debian bookworm package that softid's build, tests and benchmarks need.
# Idempotent: when everything is present it returns in about a second without touching apt.
# Used by the README commands, by .ci/run and by deploy/Dockerfile (build stage).
set -euo pipefail

packages=(
  # toolchain
  build-essential cmake ninja-build pkg-config git ca-certificates
  # numerics: Eigen, CHOLMOD (SuiteSparse) with OpenBLAS, Ceres Solver
  libeigen3-dev libsuitesparse-dev libopenblas0-pthread libceres-dev
  # modal analysis (the model's eigenfrequencies): Spectra, header-only on Eigen
  libspectra-dev
  # geometry: Embree (BVH ray casting, closest-point queries), assimp (OBJ/PLY/STL input)
  libembree-dev libassimp-dev
  # images: 16-bit PNG depth frames and plots; lens distortion (calib3d)
  libopencv-core-dev libopencv-imgcodecs-dev libopencv-imgproc-dev libopencv-calib3d-dev
  # point-cloud geometry of raw recordings: plane fitting, FPFH + RANSAC registration, ICP
  libopen3d-dev
  # service: gRPC, Protobuf, SQLite
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler libsqlite3-dev libssl-dev
  # the PostgreSQL job store (--store): libpq to build; the server 15 that its tests start
  # (tests/server/with_postgres.sh)
  libpq-dev postgresql-15
  # utilities
  libspdlog-dev libfmt-dev nlohmann-json3-dev libcli11-dev
  # the server's /metrics endpoint (HTTP)
  libcpp-httplib-dev
  # tests and benchmarks; the Python client example and its test (clients/python)
  libgtest-dev libgmock-dev libbenchmark-dev python3-grpcio python3-protobuf
  # the independent validation set (tools/validation, tests/validation): CalculiX, numpy, 16-bit PNG
  calculix-ccx python3-numpy python3-png
  # fuzzing (tests/fuzz): clang with libFuzzer and the sanitizer runtimes; llvm-14 for
  # llvm-symbolizer, which puts file and line into the stack trace of a crash
  clang-14 libclang-rt-14-dev llvm-14
  # OpenMP for clang: the whole project is configured in the fuzz build (core/ingest needs it)
  libomp-14-dev
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ "${#missing[@]}" -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

echo "install-deps: installing ${#missing[@]} packages: ${missing[*]}"
sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install-deps: done"
