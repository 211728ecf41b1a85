#include "server/proto_conversion.h"

#include <google/protobuf/util/time_util.h>

#include <limits>

#include "core/fem/parameter_registry.h"

namespace softid::server {
namespace {

void SetTimestamp(store::Timestamp t, google::protobuf::Timestamp* out) {
  *out = google::protobuf::util::TimeUtil::MicrosecondsToTimestamp(store::ToUnixMicros(t));
}

}  // namespace

v1::JobState ToProto(store::JobState state) {
  switch (state) {
    case store::JobState::kQueued: return v1::QUEUED;
    case store::JobState::kRunning: return v1::RUNNING;
    case store::JobState::kSucceeded: return v1::SUCCEEDED;
    case store::JobState::kFailed: return v1::FAILED;
    case store::JobState::kCancelled: return v1::CANCELLED;
  }
  return v1::JOB_STATE_UNSPECIFIED;
}

ServiceResult<std::optional<store::JobState>> StateFilterFromProto(v1::JobState state) {
  switch (state) {
    case v1::JOB_STATE_UNSPECIFIED: return std::optional<store::JobState>();
    case v1::QUEUED: return std::optional(store::JobState::kQueued);
    case v1::RUNNING: return std::optional(store::JobState::kRunning);
    case v1::SUCCEEDED: return std::optional(store::JobState::kSucceeded);
    case v1::FAILED: return std::optional(store::JobState::kFailed);
    case v1::CANCELLED: return std::optional(store::JobState::kCancelled);
    default: break;
  }
  return ServiceStatus(ServiceCode::kInvalidArgument,
                       "state = " + std::to_string(static_cast<int>(state)) + ": not a JobState");
}

void ToProto(const store::Capture& capture, v1::Capture* out) {
  out->set_id(capture.id);
  out->set_request_id(capture.request_id);
  int64_t total_bytes = 0;
  for (const store::ManifestEntry& entry : capture.manifest) {
    v1::CaptureFile* file = out->add_files();
    file->set_path(entry.path);
    file->set_size_bytes(entry.size_bytes);
    file->set_sha256(entry.sha256);
    total_bytes += entry.size_bytes;
  }
  out->set_num_files(static_cast<int32_t>(capture.manifest.size()));
  out->set_total_bytes(total_bytes);
  SetTimestamp(capture.created_at, out->mutable_create_time());
  out->set_format(capture.format);
}

void ToProto(const store::CaptureListing& listing, v1::Capture* out) {
  ToProto(listing.capture, out);
  out->clear_files();
  out->set_num_jobs(static_cast<int32_t>(listing.num_jobs));
}

namespace {

// Every number of a JSON value, depth first (objects in key order); null counts as +inf (the
// result's way of writing an undetermined uncertainty).
void AppendNumbers(const nlohmann::json& value, google::protobuf::RepeatedField<double>* out) {
  if (value.is_number()) {
    out->Add(value.get<double>());
  } else if (value.is_null()) {
    out->Add(std::numeric_limits<double>::infinity());
  } else if (value.is_array() || value.is_object()) {
    for (const nlohmann::json& element : value) AppendNumbers(element, out);
  }
}

}  // namespace

void FittedParametersToProto(const nlohmann::json& result, v1::Result* out) {
  const auto parameters = result.find("parameters");
  if (parameters == result.end() || !parameters->is_object()) return;
  for (const auto& [name, entry] : parameters->items()) {
    if (!entry.is_object() || !entry.contains("value")) continue;
    v1::FittedParameter* parameter = out->add_parameters();
    parameter->set_name(name);
    parameter->set_unit(entry.value("unit", std::string()));
    AppendNumbers(entry["value"], parameter->mutable_value());
    if (entry.contains("initial")) AppendNumbers(entry["initial"], parameter->mutable_initial());
    if (entry.contains("standard_uncertainty")) {
      AppendNumbers(entry["standard_uncertainty"], parameter->mutable_standard_uncertainty());
    }
    const auto discretisation = entry.find("discretisation_error");
    if (discretisation != entry.end() && discretisation->is_object() &&
        discretisation->contains("total")) {
      AppendNumbers((*discretisation)["total"], parameter->mutable_discretisation_error());
    }
  }
}

void ToProto(const store::Job& job, v1::Job* out) {
  out->set_id(job.id);
  out->set_request_id(job.request_id);
  out->set_capture_id(job.capture_id);
  out->set_config_json(job.config.dump());
  out->set_state(ToProto(job.state));
  out->set_cancel_requested(job.cancel_requested);
  out->set_attempts(job.attempts);
  out->set_error(job.error);
  SetTimestamp(job.created_at, out->mutable_create_time());
  if (job.started_at) SetTimestamp(*job.started_at, out->mutable_start_time());
  if (job.finished_at) SetTimestamp(*job.finished_at, out->mutable_end_time());
  out->set_derived_capture_id(job.derived_capture_id);
}

void ToProto(const store::ProgressEvent& event, const store::Job& job, v1::JobEvent* out) {
  out->set_seq(event.seq);
  out->set_kind(event.kind == store::ProgressKind::kIteration ? v1::JobEvent::ITERATION
                                                              : v1::JobEvent::STATE_CHANGE);
  out->set_attempt(event.attempt);
  out->set_iteration(event.iteration);
  out->set_cost(event.cost);
  out->set_gradient_norm(event.gradient_norm);
  if (!event.parameters.is_null()) {
    out->set_parameters_json(event.parameters.dump());
    if (event.parameters.is_object()) {
      for (const auto& [name, value] : event.parameters.items()) {
        const std::string_view unit = fem::ParameterUnit(name);
        if (!unit.empty()) (*out->mutable_parameter_units())[name] = std::string(unit);
      }
    }
  }
  // Iteration events happen while RUNNING; the store records a state only for state changes.
  out->set_state(event.state ? ToProto(*event.state) : v1::RUNNING);
  out->set_elapsed_seconds(event.elapsed_s);
  out->set_message(event.message);
  SetTimestamp(event.created_at, out->mutable_create_time());
  // The job config's defaults when the keys are absent (job_config.h).
  int max_iterations = 50;
  if (auto it = job.config.find("max_iterations");
      it != job.config.end() && it->is_number_integer()) {
    max_iterations = it->get<int>();
  }
  if (auto it = job.config.find("refine_iterations");
      it != job.config.end() && it->is_number_integer()) {
    max_iterations += it->get<int>();
  }
  out->set_max_iterations(max_iterations);
  out->set_start(event.start);
  out->set_num_starts(event.num_starts);
  out->set_remaining_seconds(event.remaining_s);
}

UploadManifest FromProto(const v1::CaptureManifest& manifest) {
  UploadManifest out;
  out.request_id = manifest.request_id();
  out.capture_json = manifest.capture_json();
  out.recording_json = manifest.recording_json();
  for (const v1::CaptureFile& file : manifest.files()) {
    out.files.push_back({file.path(), file.sha256(), file.size_bytes()});
  }
  return out;
}

}  // namespace softid::server
