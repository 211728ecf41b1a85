#!/usr/bin/env python3
"""A softid client in Python: upload a capture folder, queue a job, watch it, save the result.

    ./generate.sh                      # the API's Python modules into ./gen (once)
    python3 softid_client.py --server HOST:50051 [--token T] [--tls-ca CA.pem] \\
        CAPTURE_DIR --config job.json --out result.json

The same calls as the `softid` client, from the API alone (proto/softid/v1/softid.proto).
"""
import argparse
import hashlib
import json
import math
import os
import pathlib
import sys

import grpc

sys.path.insert(0, os.environ.get("SOFTID_PYTHON_GEN", str(pathlib.Path(__file__).parent / "gen")))
from softid.v1 import softid_pb2 as pb  # noqa: E402
from softid.v1 import softid_pb2_grpc as pb_grpc  # noqa: E402

CHUNK_BYTES = 1 << 20  # the API's largest chunk


def capture_files(folder):
    """capture.json's text and the manifest entries of every file it names (mesh, frames)."""
    text = (folder / "capture.json").read_text()
    capture = json.loads(text)
    paths = [capture["mesh"]] + [f for cam in capture["cameras"] for f in cam["frames"]]
    files = []
    for path in dict.fromkeys(paths):  # unique, in order
        data = (folder / path).read_bytes()
        files.append(pb.CaptureFile(path=path, size_bytes=len(data),
                                    sha256=hashlib.sha256(data).hexdigest()))
    return text, files


def upload_requests(folder, capture_json, files):
    yield pb.UploadCaptureRequest(manifest=pb.CaptureManifest(capture_json=capture_json,
                                                              files=files))
    for entry in files:
        data = (folder / entry.path).read_bytes()
        for offset in range(0, len(data), CHUNK_BYTES):
            yield pb.UploadCaptureRequest(chunk=pb.FileChunk(
                path=entry.path, offset_bytes=offset, data=data[offset:offset + CHUNK_BYTES]))


def channel(server, tls_ca):
    if not tls_ca:
        return grpc.insecure_channel(server)
    return grpc.secure_channel(server, grpc.ssl_channel_credentials(pathlib.Path(tls_ca).read_bytes()))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("capture", type=pathlib.Path, help="capture folder (with capture.json)")
    parser.add_argument("--config", type=pathlib.Path, help="job config JSON (default: {})")
    parser.add_argument("--out", default="result.json", help="where to write result.json")
    parser.add_argument("--server", default=os.environ.get("SOFTID_SERVER", "localhost:50051"))
    parser.add_argument("--token", default=os.environ.get("SOFTID_TOKEN", ""))
    parser.add_argument("--tls-ca", default=os.environ.get("SOFTID_TLS_CA", ""))
    args = parser.parse_args()

    metadata = [("authorization", "Bearer " + args.token)] if args.token else []
    stub = pb_grpc.ReconstructionStub(channel(args.server, args.tls_ca))
    capture_json, files = capture_files(args.capture)
    capture = stub.UploadCapture(upload_requests(args.capture, capture_json, files),
                                 metadata=metadata)
    print(f"capture {capture.id}: {len(capture.files)} files")
    config = args.config.read_text() if args.config else "{}"
    job = stub.CreateJob(pb.CreateJobRequest(capture_id=capture.id, config_json=config),
                         metadata=metadata)
    print(f"job {job.id}: {pb.JobState.Name(job.state)}")

    state = job.state
    for event in stub.WatchJob(pb.WatchJobRequest(job_id=job.id), metadata=metadata):
        state = event.state
        if event.kind == pb.JobEvent.ITERATION and not math.isnan(event.cost):
            print(f"  start {event.start + 1}/{event.num_starts} iteration {event.iteration}/"
                  f"{event.max_iterations}: cost {event.cost:.4g} m^2 {event.parameters_json}")
        elif event.kind == pb.JobEvent.STATE_CHANGE:
            print(f"  {pb.JobState.Name(event.state)} {event.message}")
    if state != pb.SUCCEEDED:
        job = stub.GetJob(pb.GetJobRequest(job_id=job.id), metadata=metadata)
        print(f"job {job.id} ended {pb.JobState.Name(job.state)}: {job.error}", file=sys.stderr)
        return 1

    result = stub.GetResult(pb.GetResultRequest(job_id=job.id), metadata=metadata)
    pathlib.Path(args.out).write_text(result.result_json)
    for name, entry in json.loads(result.result_json)["parameters"].items():
        print(f"{name} = {entry['value']} {entry.get('unit', '')}")
    print(f"result written to {args.out}")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except grpc.RpcError as error:
        print(f"softid: {error.code().name}: {error.details()}", file=sys.stderr)
        sys.exit(1)
