#!/usr/bin/env bash
# Usage: generate.sh [PROTO_DIR] [OUT_DIR]
# Generates the Python modules of the softid API (softid/v1/softid_pb2.py and _pb2_grpc.py) with
# Debian's protoc and gRPC Python plugin (packages protobuf-compiler and protobuf-compiler-grpc),
# which match the runtime packages python3-protobuf and python3-grpcio. PROTO_DIR defaults to the
# installed API (/usr/share/softid/proto, package softid-client), else this repository's proto/.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
proto_dir=${1:-/usr/share/softid/proto}
[ -f "$proto_dir/softid/v1/softid.proto" ] || proto_dir=$here/../../proto
out_dir=${2:-$here/gen}
mkdir -p "$out_dir"
protoc --proto_path="$proto_dir" --python_out="$out_dir" --grpc_out="$out_dir" \
  --plugin=protoc-gen-grpc="$(command -v grpc_python_plugin)" "$proto_dir/softid/v1/softid.proto"
echo "$out_dir"
