// softid: the command-line client of the softid job server. Talks only gRPC.
//
// Exit codes: 0 ok, 2 invalid input (INVALID_ARGUMENT, ALREADY_EXISTS, bad local files or flags),
// 3 not found, 4 server unreachable (UNAVAILABLE or deadline exceeded after retries), 1 anything
// else (including a job that ended FAILED or CANCELLED under --wait).
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>

#include "client/capture_download.h"
#include "client/capture_files.h"
#include "client/channel_credentials.h"
#include "client/progress_printer.h"
#include "client/reconstruction_client.h"
#include "client/text_format.h"

namespace {

using softid::client::Compact;
using softid::client::ProgressPrinter;
using softid::client::ReconstructionClient;
using softid::client::StateName;
namespace v1 = softid::v1;

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitInvalidInput = 2;
constexpr int kExitNotFound = 3;
constexpr int kExitUnreachable = 4;

struct GlobalFlags {
  std::string server;
  bool json = false;
  double timeout_s = 10.0;
  double retry_for_s = 30.0;
  softid::client::TlsClientOptions tls;
  std::string token;
};

int ExitCodeOf(const grpc::Status& status) {
  switch (status.error_code()) {
    case grpc::StatusCode::OK: return kExitOk;
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::ALREADY_EXISTS:
    case grpc::StatusCode::OUT_OF_RANGE: return kExitInvalidInput;
    case grpc::StatusCode::NOT_FOUND: return kExitNotFound;
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::DEADLINE_EXCEEDED: return kExitUnreachable;
    default: return kExitFailure;
  }
}

int Report(const grpc::Status& status, const GlobalFlags& flags) {
  static const char* kCodes[] = {"OK",
                                 "CANCELLED",
                                 "UNKNOWN",
                                 "INVALID_ARGUMENT",
                                 "DEADLINE_EXCEEDED",
                                 "NOT_FOUND",
                                 "ALREADY_EXISTS",
                                 "PERMISSION_DENIED",
                                 "RESOURCE_EXHAUSTED",
                                 "FAILED_PRECONDITION",
                                 "ABORTED",
                                 "OUT_OF_RANGE",
                                 "UNIMPLEMENTED",
                                 "INTERNAL",
                                 "UNAVAILABLE",
                                 "DATA_LOSS",
                                 "UNAUTHENTICATED"};
  const int code = static_cast<int>(status.error_code());
  const char* name = code >= 0 && code <= 16 ? kCodes[code] : "UNKNOWN";
  std::string message = status.error_message();
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE) {
    message = "cannot reach " + flags.server + ": " + message;
  }
  std::fprintf(stderr, "softid: %s: %s\n", name, message.c_str());
  return ExitCodeOf(status);
}

bool IsTerminal(v1::JobState state) {
  return state == v1::SUCCEEDED || state == v1::FAILED || state == v1::CANCELLED;
}

nlohmann::json JobJson(const v1::Job& job) {
  nlohmann::json out = {{"id", job.id()},
                        {"capture_id", job.capture_id()},
                        {"state", StateName(job.state())},
                        {"attempts", job.attempts()},
                        {"cancel_requested", job.cancel_requested()},
                        {"config", nlohmann::json::parse(job.config_json(), nullptr, false)},
                        {"create_time_s", job.create_time().seconds()}};
  if (!job.request_id().empty()) out["request_id"] = job.request_id();
  if (!job.error().empty()) out["error"] = job.error();
  if (!job.derived_capture_id().empty()) out["derived_capture_id"] = job.derived_capture_id();
  return out;
}

void PrintJob(const v1::Job& job, const GlobalFlags& flags) {
  if (flags.json) {
    std::cout << JobJson(job).dump() << "\n";
    return;
  }
  std::cout << job.id() << "  " << StateName(job.state()) << "  capture " << job.capture_id()
            << "  attempts " << job.attempts();
  if (job.cancel_requested() && !IsTerminal(job.state())) std::cout << "  (cancel requested)";
  if (!job.derived_capture_id().empty()) {
    std::cout << "\n  ingested into capture " << job.derived_capture_id();
  }
  if (!job.error().empty()) std::cout << "\n  error: " << job.error();
  std::cout << "\n";
}

// |recovered - truth| / |truth| for numbers, the same with Euclidean norms for vectors.
std::optional<double> RelativeError(const nlohmann::json& value, const nlohmann::json& truth) {
  if (value.is_number() && truth.is_number()) {
    const double t = truth.get<double>();
    if (t == 0.0) return std::nullopt;
    return std::abs(value.get<double>() - t) / std::abs(t);
  }
  if (value.is_array() && truth.is_array() && value.size() == truth.size()) {
    double diff = 0.0, norm = 0.0;
    for (size_t i = 0; i < value.size(); ++i) {
      if (!value[i].is_number() || !truth[i].is_number()) return std::nullopt;
      diff += std::pow(value[i].get<double>() - truth[i].get<double>(), 2);
      norm += std::pow(truth[i].get<double>(), 2);
    }
    if (norm == 0.0) return std::nullopt;
    return std::sqrt(diff / norm);
  }
  return std::nullopt;
}

// The fitted parameters next to the truth of a synthetic capture (softid-lab synth's
// truth.json: {"parameters": {name: value}}). False with `error` set for an unreadable truth file.
bool PrintAgainstTruth(const nlohmann::json& result, const std::string& truth_file,
                       std::string* error) {
  std::ifstream in(truth_file);
  if (!in) {
    *error = truth_file + ": cannot be read";
    return false;
  }
  const nlohmann::json truth = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (truth.is_discarded() || !truth.contains("parameters") || !truth["parameters"].is_object()) {
    *error = truth_file + ": not a truth file (expected {\"parameters\": {...}})";
    return false;
  }
  const nlohmann::json& parameters = result.value("parameters", nlohmann::json::object());
  std::printf("%-24s %-20s %-20s %-20s %-10s %-20s %-20s %s\n", "parameter", "recovered", "1-sigma",
              "discretisation", "unit", "start", "truth", "error");
  for (const auto& [name, entry] : parameters.items()) {
    const std::string key = name == "ground_plane" ? "ground" : name;
    const nlohmann::json value = entry.value("value", nlohmann::json());
    const nlohmann::json* true_value =
        truth["parameters"].contains(key) ? &truth["parameters"][key] : nullptr;
    std::string error_text = "-";
    if (true_value != nullptr) {
      if (const std::optional<double> e = RelativeError(value, *true_value)) {
        char text[32];
        std::snprintf(text, sizeof(text), "%.2f %%", 100.0 * *e);
        error_text = text;
      }
    }
    const std::string sigma = !entry.contains("standard_uncertainty") ? "-"
                              : entry["standard_uncertainty"].is_null()
                                  ? "undetermined"
                                  : Compact(entry["standard_uncertainty"]);
    // The grid and time step's estimated bias (docs/results.md), beside the noise's sigma.
    const auto discretisation = entry.find("discretisation_error");
    const std::string bias =
        discretisation == entry.end() || !discretisation->is_object() ? "-"
        : !discretisation->contains("total") || (*discretisation)["total"].is_null()
            ? "undetermined"
            : Compact((*discretisation)["total"]);
    std::printf("%-24s %-20s %-20s %-20s %-10s %-20s %-20s %s\n", name.c_str(),
                Compact(value).c_str(), sigma.c_str(), bias.c_str(),
                entry.value("unit", std::string()).c_str(),
                Compact(entry.value("initial", nlohmann::json())).c_str(),
                true_value != nullptr ? Compact(*true_value).c_str() : "-", error_text.c_str());
  }
  const nlohmann::json& cost = result.value("cost", nlohmann::json::object());
  if (cost.contains("initial") && cost.contains("final")) {
    std::printf("cost %s -> %s m^2 after %s iterations\n", Compact(cost["initial"]).c_str(),
                Compact(cost["final"]).c_str(),
                Compact(result.value("iterations", nlohmann::json())).c_str());
  }
  return true;
}

// The client for `flags`, or nullopt after printing why the TLS files cannot be used.
std::optional<ReconstructionClient> MakeClient(const GlobalFlags& flags) {
  softid::client::ClientOptions options;
  options.call_timeout =
      std::chrono::milliseconds(static_cast<int64_t>(std::max(0.001, flags.timeout_s) * 1000));
  options.retry_budget = std::chrono::milliseconds(static_cast<int64_t>(flags.retry_for_s * 1000));
  options.token = flags.token;
  std::string error;
  std::shared_ptr<grpc::ChannelCredentials> credentials =
      softid::client::MakeChannelCredentials(flags.tls, &error);
  if (!credentials) {
    std::fprintf(stderr, "softid: %s\n", error.c_str());
    return std::nullopt;
  }
  return ReconstructionClient(grpc::CreateChannel(flags.server, credentials), options);
}

int WatchUntilDone(ReconstructionClient& client, const std::string& job_id,
                   const GlobalFlags& flags) {
  ProgressPrinter printer(flags.json);
  grpc::Status status = client.WatchJob(job_id, 0, [&](const v1::JobEvent& e) { printer(e); });
  if (!status.ok()) return Report(status, flags);
  v1::Job job;
  status = client.GetJob(job_id, &job);
  if (!status.ok()) return Report(status, flags);
  if (!flags.json) PrintJob(job, flags);
  return job.state() == v1::SUCCEEDED ? kExitOk : kExitFailure;
}

// "39526 +- 49.9" or "[0, 0, -9.81] +- [0.01, 0.01, 0.02]": a typed parameter in one line.
std::string ValueWithSigma(const v1::FittedParameter& parameter) {
  const auto list = [](const google::protobuf::RepeatedField<double>& numbers) {
    std::string out;
    char text[32];
    for (int i = 0; i < numbers.size(); ++i) {
      if (std::isfinite(numbers[i])) {
        std::snprintf(text, sizeof(text), "%.5g", numbers[i]);
      } else {
        std::snprintf(text, sizeof(text), "undetermined");
      }
      out += (i ? ", " : "") + std::string(text);
    }
    return numbers.size() == 1 ? out : "[" + out + "]";
  };
  std::string out = list(parameter.value());
  if (parameter.standard_uncertainty_size() > 0)
    out += " +- " + list(parameter.standard_uncertainty());
  if (parameter.discretisation_error_size() > 0)
    out += " (discretisation " + list(parameter.discretisation_error()) + ")";
  return out;
}

// A few lines on the ingest of a job on a raw recording (ingest.json, "softid-ingest/1"): the
// floor, how well the mesh registered, the frames; fields it lacks are left out.
void PrintIngestSummary(const nlohmann::json& ingest, const std::string& derived_capture_id) {
  std::printf("ingest: recording ingested into capture %s\n",
              derived_capture_id.empty() ? "?" : derived_capture_id.c_str());
  // The report comes from the server: a field of another type ends the summary, not the client.
  try {
    const nlohmann::json floor = ingest.value("floor", nlohmann::json::object());
    const nlohmann::json normal = floor.value("normal", nlohmann::json());
    if (normal.is_array() && normal.size() == 3 && floor.contains("offset_m")) {
      // Three decimals: a world frame built on the floor gives (0, 0, 1) up to rounding noise.
      std::printf("  floor         n=[%.3f, %.3f, %.3f] d=%.4g m, RMS %.2g mm, %.0f %% inliers\n",
                  normal[0].get<double>(), normal[1].get<double>(), normal[2].get<double>(),
                  floor.value("offset_m", NAN), 1e3 * floor.value("rms_m", NAN),
                  100.0 * floor.value("inlier_share", NAN));
    }
    const nlohmann::json registration = ingest.value("registration", nlohmann::json::object());
    if (registration.contains("rms_m")) {
      std::printf("  registration  RMS %.2g mm, overlap %.0f %%\n",
                  1e3 * registration.value("rms_m", NAN),
                  100.0 * registration.value("overlap", NAN));
    }
    const nlohmann::json time = ingest.value("time", nlohmann::json::object());
    if (time.contains("frames")) {
      std::printf("  frames        %d (median interval %.3g ms, largest gap %.3g ms)\n",
                  time.value("frames", 0), 1e3 * time.value("median_interval_s", NAN),
                  1e3 * time.value("max_gap_s", NAN));
    }
  } catch (const nlohmann::json::exception&) {
    std::printf("  (the ingest report is not in the expected form; see result.json)\n");
  }
}

// The result of a job: a table of the typed parameters with their 1-sigma (or, with --json and
// no -o, result.json itself), after an ingest summary for a job on a recording; -o also writes
// result.json; --truth compares with a truth.json; --report downloads the job's pictures.
int ShowResult(ReconstructionClient& client, const std::string& job_id, const std::string& out_file,
               const std::string& truth_file, const std::string& report_dir,
               const GlobalFlags& flags) {
  v1::Result r;
  const grpc::Status s = client.GetResult(job_id, &r);
  if (!s.ok()) return Report(s, flags);
  if (!report_dir.empty()) {
    const grpc::Status downloaded = client.DownloadReport(r, report_dir);
    if (!downloaded.ok()) return Report(downloaded, flags);
    if (!flags.json) {
      std::printf("report: %d file(s) written to %s\n", r.artifacts_size(), report_dir.c_str());
    }
  }
  const nlohmann::json parsed = nlohmann::json::parse(r.result_json(), nullptr, false);
  if (parsed.is_discarded()) {
    std::fprintf(stderr, "softid: job %s: the server sent a result that is not JSON\n",
                 job_id.c_str());
    return kExitFailure;
  }
  if (!truth_file.empty()) {
    std::string error;
    if (!PrintAgainstTruth(parsed, truth_file, &error)) {
      std::fprintf(stderr, "softid: --truth %s\n", error.c_str());
      return kExitInvalidInput;
    }
  } else if (flags.json && out_file.empty()) {
    std::cout << parsed.dump(2) << "\n";
    return kExitOk;
  } else if (!flags.json) {
    if (!r.ingest_json().empty()) {
      v1::Job job;  // for its derived capture; the summary stands without it
      (void)client.GetJob(job_id, &job);
      PrintIngestSummary(nlohmann::json::parse(r.ingest_json(), nullptr, false),
                         job.derived_capture_id());
    }
    for (const v1::FittedParameter& parameter : r.parameters()) {
      std::printf("%-26s %s %s\n", parameter.name().c_str(), ValueWithSigma(parameter).c_str(),
                  parameter.unit().c_str());
    }
  }
  if (out_file.empty()) return kExitOk;
  std::ofstream out(out_file);
  out << parsed.dump(2) << "\n";
  if (!out.flush()) {
    std::fprintf(stderr, "softid: %s: cannot write\n", out_file.c_str());
    return kExitFailure;
  }
  if (!flags.json) std::cout << "result written to " << out_file << "\n";
  return kExitOk;
}

// Uploads the capture or raw recording folder `dir` and sets its id; an exit code.
int UploadCaptureFolder(ReconstructionClient& client, const std::string& dir,
                        const std::string& request_id, const GlobalFlags& flags,
                        std::string* capture_id) {
  softid::client::CaptureFiles files;
  std::string error;
  if (!softid::client::ReadFolderFiles(dir, &files, &error)) {
    std::fprintf(stderr, "softid: %s\n", error.c_str());
    return kExitInvalidInput;
  }
  v1::Capture capture;
  int skipped = 0;
  const grpc::Status s = client.UploadCapture(
      files, request_id.empty() ? "" : request_id + "/capture", &capture, &skipped);
  if (!s.ok()) return Report(s, flags);
  if (!flags.json) {
    std::cout << (files.recording_json.empty() ? "capture " : "recording ") << capture.id()
              << " uploaded (" << files.files.size() << " files";
    if (skipped > 0) std::cout << ", " << skipped << " of them already on the server";
    std::cout << ")\n";
  }
  *capture_id = capture.id();
  return kExitOk;
}

// Every capture the caller may see, a line each (or one JSON array).
int ListCaptures(ReconstructionClient& client, const GlobalFlags& flags) {
  v1::ListCapturesRequest request;
  nlohmann::json all = nlohmann::json::array();
  do {
    v1::ListCapturesResponse page;
    const grpc::Status s = client.ListCaptures(request, &page);
    if (!s.ok()) return Report(s, flags);
    for (const v1::Capture& capture : page.captures()) {
      if (flags.json) {
        all.push_back({{"id", capture.id()},
                       {"request_id", capture.request_id()},
                       {"num_files", capture.num_files()},
                       {"total_bytes", capture.total_bytes()},
                       {"num_jobs", capture.num_jobs()},
                       {"format", capture.format()},
                       {"create_time_s", capture.create_time().seconds()}});
        continue;
      }
      std::printf("%s  %-9s  %4d files  %8.1f MB  %3d job(s)%s%s\n", capture.id().c_str(),
                  capture.format() == "softid-recording/1" ? "recording" : "capture",
                  capture.num_files(), capture.total_bytes() / 1e6, capture.num_jobs(),
                  capture.request_id().empty() ? "" : "  request ", capture.request_id().c_str());
    }
    request.set_page_token(page.next_page_token());
  } while (!request.page_token().empty());
  if (flags.json) std::cout << all.dump() << "\n";
  return kExitOk;
}

// Downloads capture `capture_id` into `dir` (absent or empty); an exit code.
int DownloadCapture(ReconstructionClient& client, const std::string& capture_id,
                    const std::string& dir, const GlobalFlags& flags) {
  std::string error;
  if (!softid::client::IsEmptyTarget(dir, &error)) {
    std::fprintf(stderr, "softid: -o %s\n", error.c_str());
    return kExitInvalidInput;
  }
  v1::Capture capture;
  const grpc::Status s = client.DownloadCapture(capture_id, dir, &capture);
  if (!s.ok()) return Report(s, flags);
  if (flags.json) {
    std::cout << nlohmann::json{{"id", capture.id()},
                                {"format", capture.format()},
                                {"num_files", capture.files_size()},
                                {"directory", dir}}
                     .dump()
              << "\n";
  } else {
    std::cout << "capture " << capture.id() << " (" << capture.files_size() << " files) written to "
              << dir << "\n";
  }
  return kExitOk;
}

// Uploads the folder (unless an uploaded capture is named) and queues a job on it; with `wait`,
// follows it to its end.
int Submit(ReconstructionClient& client, const std::string& capture_dir,
           const std::string& config_file, const std::string& request_id, std::string capture_id,
           bool wait, const GlobalFlags& flags) {
  v1::CreateJobRequest create;
  if (!config_file.empty()) {
    std::ifstream in(config_file);
    if (!in) {
      std::fprintf(stderr, "softid: %s: cannot read the job config\n", config_file.c_str());
      return kExitInvalidInput;
    }
    std::stringstream text;
    text << in.rdbuf();
    create.set_config_json(text.str());
  }
  if (capture_id.empty()) {
    const int uploaded = UploadCaptureFolder(client, capture_dir, request_id, flags, &capture_id);
    if (uploaded != kExitOk) return uploaded;
  }
  create.set_capture_id(capture_id);
  create.set_request_id(request_id);
  v1::Job job;
  const grpc::Status s = client.CreateJob(create, &job);
  if (!s.ok()) return Report(s, flags);
  if (flags.json) {
    std::cout << JobJson(job).dump() << "\n";
  } else {
    std::cout << "job " << job.id() << " " << StateName(job.state()) << " on capture " << capture_id
              << "\n";
  }
  return wait ? WatchUntilDone(client, job.id(), flags) : kExitOk;
}

// The caller's jobs, all pages, optionally in one state.
int ListJobs(ReconstructionClient& client, const std::string& state, const GlobalFlags& flags) {
  v1::ListJobsRequest request;
  if (!state.empty()) {
    v1::JobState parsed;
    if (!v1::JobState_Parse(state, &parsed) || parsed == v1::JOB_STATE_UNSPECIFIED) {
      std::fprintf(stderr,
                   "softid: --state = %s: must be QUEUED, RUNNING, SUCCEEDED, FAILED "
                   "or CANCELLED\n",
                   state.c_str());
      return kExitInvalidInput;
    }
    request.set_state(parsed);
  }
  nlohmann::json all = nlohmann::json::array();
  do {
    v1::ListJobsResponse page;
    grpc::Status s = client.ListJobs(request, &page);
    if (!s.ok()) return Report(s, flags);
    for (const v1::Job& job : page.jobs()) {
      if (flags.json) {
        all.push_back(JobJson(job));
      } else {
        PrintJob(job, flags);
      }
    }
    request.set_page_token(page.next_page_token());
  } while (!request.page_token().empty());
  if (flags.json) std::cout << all.dump() << "\n";
  return kExitOk;
}

int Health(ReconstructionClient& client, const GlobalFlags& flags) {
  softid::client::ServingStatus serving;
  grpc::Status s = client.Health("", &serving);
  if (!s.ok()) return Report(s, flags);
  if (flags.json) {
    std::cout << nlohmann::json{{"status", ToString(serving)}}.dump() << "\n";
  } else {
    std::cout << ToString(serving) << "\n";
  }
  return serving == softid::client::ServingStatus::kServing ? kExitOk : kExitUnreachable;
}

// The values the subcommands' arguments and options write into.
struct CommandArgs {
  std::string capture_dir, config_file, request_id, job_id, out_file, truth_file, report_dir, state;
  bool wait = false;
  std::string capture_id;
};

// The subcommands, to tell after parsing which one was given.
struct Subcommands {
  CLI::App* submit = nullptr;
  CLI::App* status = nullptr;
  CLI::App* watch = nullptr;
  CLI::App* result = nullptr;
  CLI::App* list = nullptr;
  CLI::App* cancel = nullptr;
  CLI::App* health = nullptr;
  CLI::App* captures = nullptr;
  CLI::App* delete_job = nullptr;
  CLI::App* delete_capture = nullptr;
  CLI::App* download = nullptr;
};

void AddGlobalOptions(CLI::App& app, GlobalFlags& flags) {
  app.add_option("--server", flags.server, "server address host:port (env SOFTID_SERVER)")
      ->capture_default_str();
  app.add_flag("--json", flags.json, "machine-readable output");
  app.add_option("--timeout", flags.timeout_s, "deadline of each call, seconds")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--retry-for", flags.retry_for_s,
                 "keep retrying this long while the server is unavailable, seconds")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--token", flags.token, "this station's API token (env SOFTID_TOKEN)")
      ->envname("SOFTID_TOKEN");
  app.add_flag("--tls", flags.tls.enabled, "connect over TLS (system root certificates)")
      ->envname("SOFTID_TLS");
  app.add_option("--tls-ca", flags.tls.ca_file,
                 "CA bundle (PEM) the server's certificate must chain to; implies --tls")
      ->envname("SOFTID_TLS_CA");
  app.add_option("--tls-cert", flags.tls.cert_file, "client certificate (PEM) for mutual TLS")
      ->envname("SOFTID_TLS_CERT");
  app.add_option("--tls-key", flags.tls.key_file, "the client certificate's private key (PEM)")
      ->envname("SOFTID_TLS_KEY");
}

CLI::App* AddSubmitCommand(CLI::App& app, CommandArgs& args) {
  CLI::App* submit =
      app.add_subcommand("submit", "upload a capture or raw recording folder and queue a job");
  CLI::Option* dir_option = submit->add_option(
      "capture_dir", args.capture_dir,
      "capture folder (capture.json) or raw recording folder (recording.json; the job ingests it)");
  CLI::Option* capture_option =
      submit->add_option("--capture", args.capture_id,
                         "queue the job on this uploaded capture instead (see `captures`)");
  dir_option->excludes(capture_option);
  submit->callback([&args] {
    if (args.capture_dir.empty() && args.capture_id.empty()) {
      throw CLI::ValidationError("submit", "give a capture folder or --capture ID");
    }
  });
  submit->add_option("-c,--config", args.config_file,
                     "job config JSON (default: fit youngs_modulus)");
  submit->add_option("--request-id", args.request_id, "idempotency key for retried submissions");
  submit->add_flag("--wait", args.wait, "watch the job until it ends");
  submit->footer(
      "Examples:\n"
      "  softid submit capture/ --config job.json --wait\n"
      "  softid submit recording/ --config job.json     # a raw recording: the job ingests it\n"
      "  softid submit --capture cap-0123456789abcdef --config job2.json");
  return submit;
}

// The subcommands on one job or the list of them, after `submit`: status, watch, result, list,
// cancel.
void AddJobCommands(CLI::App& app, CommandArgs& args, Subcommands* commands) {
  commands->status = app.add_subcommand("status", "show a job");
  commands->status->add_option("job", args.job_id, "the job's id (job-...)")->required();
  commands->status->footer("Example:\n  softid status job-0123456789abcdef");
  commands->watch = app.add_subcommand("watch", "follow a job's progress until it ends");
  commands->watch->add_option("job", args.job_id, "the job's id (job-...)")->required();
  commands->watch->footer(
      "Example:\n  softid watch job-0123456789abcdef     # --json: one event per line");
  CLI::App* result = app.add_subcommand("result", "print or save the result of a job");
  result->add_option("job", args.job_id, "the job's id (job-...)")->required();
  result->add_option("-o,--out", args.out_file, "also write result.json here");
  result->add_option("--truth", args.truth_file,
                     "print the fitted parameters next to this truth.json (softid-lab synth)");
  result->add_option("--report", args.report_dir,
                     "download the job's report (PNG plots) into this new or empty folder");
  result->footer(
      "Examples:\n"
      "  softid result job-0123456789abcdef\n"
      "  softid result job-0123456789abcdef -o result.json --report report/\n"
      "  softid result job-0123456789abcdef --truth capture/truth.json");
  commands->result = result;
  commands->list = app.add_subcommand("list", "list jobs");
  commands->list->add_option("--state", args.state,
                             "QUEUED, RUNNING, SUCCEEDED, FAILED or CANCELLED");
  commands->list->footer("Example:\n  softid list --state RUNNING");
  commands->cancel = app.add_subcommand("cancel", "cancel a job");
  commands->cancel->add_option("job", args.job_id, "the job's id (job-...)")->required();
  commands->cancel->footer("Example:\n  softid cancel job-0123456789abcdef");
}

// The remaining subcommands, in this order: health, captures, delete, delete-capture, download.
void AddServerAndCaptureCommands(CLI::App& app, CommandArgs& args, Subcommands* commands) {
  commands->health = app.add_subcommand("health", "check that the server is serving");
  commands->health->footer("Example:\n  softid --server host:50051 --tls-ca ca.pem health");
  commands->captures = app.add_subcommand("captures", "list uploaded captures");
  commands->captures->footer("Example:\n  softid captures --json");
  commands->delete_job = app.add_subcommand("delete", "delete a job that is not running");
  commands->delete_job->add_option("job", args.job_id, "the job's id (job-...)")->required();
  commands->delete_job->footer("Example:\n  softid delete job-0123456789abcdef");
  commands->delete_capture = app.add_subcommand(
      "delete-capture", "delete an uploaded capture that no job uses (delete its jobs first)");
  commands->delete_capture->add_option("capture", args.capture_id, "the capture's id (cap-...)")
      ->required();
  commands->delete_capture->footer("Example:\n  softid delete-capture cap-0123456789abcdef");
  CLI::App* download = app.add_subcommand(
      "download", "download an uploaded or derived capture's files into a new or empty folder");
  download->add_option("capture", args.capture_id, "the capture's id (cap-...)")->required();
  download->add_option("-o,--out", args.out_file, "folder to write (must not exist or be empty)")
      ->required();
  download->footer("Example:\n  softid download cap-0123456789abcdef -o capture/");
  commands->download = download;
}

// `status` (GetJob) or `cancel` (CancelJob): the job the call returns, printed.
int ShowJob(ReconstructionClient& client, const std::string& job_id, bool cancel,
            const GlobalFlags& flags) {
  v1::Job job;
  grpc::Status s = cancel ? client.CancelJob(job_id, &job) : client.GetJob(job_id, &job);
  if (!s.ok()) return Report(s, flags);
  PrintJob(job, flags);
  return kExitOk;
}

// `delete` (a job) or `delete-capture`.
int Delete(ReconstructionClient& client, bool job, const CommandArgs& args,
           const GlobalFlags& flags) {
  const grpc::Status s =
      job ? client.DeleteJob(args.job_id) : client.DeleteCapture(args.capture_id);
  if (!s.ok()) return Report(s, flags);
  if (flags.json) {
    std::cout << nlohmann::json{{"deleted", job ? args.job_id : args.capture_id}}.dump() << "\n";
  } else {
    std::cout << (job ? args.job_id : args.capture_id) << " deleted\n";
  }
  return kExitOk;
}

// Runs the one subcommand that was parsed; an exit code.
int RunCommand(ReconstructionClient& client, const Subcommands& commands, const CommandArgs& args,
               const GlobalFlags& flags) {
  if (commands.submit->parsed()) {
    return Submit(client, args.capture_dir, args.config_file, args.request_id, args.capture_id,
                  args.wait, flags);
  }
  if (commands.status->parsed()) return ShowJob(client, args.job_id, /*cancel=*/false, flags);
  if (commands.watch->parsed()) return WatchUntilDone(client, args.job_id, flags);
  if (commands.delete_job->parsed() || commands.delete_capture->parsed()) {
    return Delete(client, commands.delete_job->parsed(), args, flags);
  }
  if (commands.result->parsed()) {
    return ShowResult(client, args.job_id, args.out_file, args.truth_file, args.report_dir, flags);
  }
  if (commands.list->parsed()) return ListJobs(client, args.state, flags);
  if (commands.cancel->parsed()) return ShowJob(client, args.job_id, /*cancel=*/true, flags);
  if (commands.captures->parsed()) return ListCaptures(client, flags);
  if (commands.download->parsed()) {
    return DownloadCapture(client, args.capture_id, args.out_file, flags);
  }
  if (commands.health->parsed()) return Health(client, flags);
  return kExitInvalidInput;
}

}  // namespace

int main(int argc, char** argv) {
  GlobalFlags flags;
  const char* env_server = std::getenv("SOFTID_SERVER");
  flags.server = env_server != nullptr && *env_server != '\0' ? env_server : "localhost:50051";

  CLI::App app{"softid: submit captures to a softid server and follow their jobs"};
  app.require_subcommand(1);
  AddGlobalOptions(app, flags);
  CommandArgs args;
  Subcommands commands;
  commands.submit = AddSubmitCommand(app, args);
  AddJobCommands(app, args, &commands);
  AddServerAndCaptureCommands(app, args, &commands);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? kExitOk : kExitInvalidInput;
  }
  std::optional<ReconstructionClient> made = MakeClient(flags);
  if (!made) return kExitInvalidInput;
  return RunCommand(*made, commands, args, flags);
}
