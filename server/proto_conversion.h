// Conversions between the store's types and softid.v1 messages; the only place that knows both.
#pragma once

#include "server/capture_upload.h"
#include "server/service_status.h"
#include "server/store/capture.h"
#include "server/store/job.h"
#include "server/store/job_store.h"
#include "server/store/progress_event.h"
#include "softid/v1/softid.pb.h"

namespace softid::server {

v1::JobState ToProto(store::JobState state);
// JOB_STATE_UNSPECIFIED becomes nullopt (no filter); unknown numbers are InvalidArgument.
ServiceResult<std::optional<store::JobState>> StateFilterFromProto(v1::JobState state);

void ToProto(const store::Capture& capture, v1::Capture* out);
// As listed: without the file entries, with the number of jobs using it.
void ToProto(const store::CaptureListing& listing, v1::Capture* out);
void ToProto(const store::Job& job, v1::Job* out);
// The typed parameters of a result.json ("parameters": {name: {value, unit, initial,
// standard_uncertainty}}); entries of another shape are skipped.
void FittedParametersToProto(const nlohmann::json& result, v1::Result* out);
// `job` gives the context of the event (max_iterations from its config).
void ToProto(const store::ProgressEvent& event, const store::Job& job, v1::JobEvent* out);
UploadManifest FromProto(const v1::CaptureManifest& manifest);

}  // namespace softid::server
