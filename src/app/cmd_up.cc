// teachsim up        [--scene FILE] [--http-port N] [--port-file F] ...
// teachsim worksite  --scene FILE [--listen HOST:PORT] [--token-file F] ...
// teachsim operator  --worksite HOST:PORT [--token-file F] [--http-port N] ...
//
// The two sites of DESIGN.md ("Processes"): apart, or both in one process over loopback with a
// token generated into a private temporary file. Each runs until SIGINT or SIGTERM and then shuts
// down cleanly (sessions closed, threads joined).
#include <signal.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>

#include "commands.h"
#include "teachsim/net/auth.h"
#include "teachsim/net/client.h"
#include "teachsim/operator/service.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/worksite/service.h"

namespace teachsim::app {

namespace {

struct SiteArgs {
  std::string scene;
  std::string listen = "127.0.0.1:8765";
  std::string worksite;
  std::string token_file;
  int http_port = 8080;
  std::string port_file;
  std::string web_root;
  std::string sessions = "sessions";
  double error_mm = 1.0, error_deg = 1.0;
  std::uint64_t seed = 1;
  double time_scale = 1.0;
  double link_timeout_s = 0.25;
  double browser_link_timeout_s = op::OperatorOptions{}.browser_link_timeout_s;
  std::string camera;
  bool no_recognition = false;
};

// Blocks SIGINT and SIGTERM in this thread and every thread started after it, so that sigwait
// receives them (no handler runs in the middle of a service thread).
sigset_t BlockStopSignals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  return set;
}

int WaitForStopSignal(const sigset_t& set) {
  int signal_number = 0;
  sigwait(&set, &signal_number);
  std::printf("teachsim: %s received, shutting down\n", signal_number == SIGINT ? "SIGINT" : "SIGTERM");
  std::fflush(stdout);
  return signal_number;
}

std::string WebRoot(const std::string& given) {
  const std::string root = given.empty() ? DataPath("web") : given;
  if (!std::filesystem::is_directory(root)) {
    std::fprintf(stderr, "teachsim: note: %s is not a folder; no browser UI is served\n", root.c_str());
    return "";
  }
  return root;
}

Status WritePortFile(const std::string& file, std::uint16_t port) {
  if (file.empty()) return Status::Ok();
  return json::WriteFileAtomic(file, std::to_string(port) + "\n");
}

// A fresh 256-bit token in a new private file (mode 0600) under the temporary folder.
Result<std::string> GenerateTokenFile() {
  std::random_device random;
  static const char* kHex = "0123456789abcdef";
  std::string token;
  for (int i = 0; i < 64; ++i) token += kHex[random() % 16];
  std::string dir_template = (std::filesystem::temp_directory_path() / "teachsim-XXXXXX").string();
  if (mkdtemp(dir_template.data()) == nullptr) return Status::IoError("cannot create a temporary folder for the token");
  const std::string file = (std::filesystem::path(dir_template) / "token").string();
  {
    std::ofstream out(file);
    out << token << "\n";
    if (!out) return Status::IoError(file + ": cannot write the token");
  }
  std::filesystem::permissions(file, std::filesystem::perms::owner_read | std::filesystem::perms::owner_write,
                               std::filesystem::perm_options::replace);
  return file;
}

// HOST:PORT to listen on; port 0 (a free one) is allowed here, unlike in a URL to dial.
Result<std::pair<std::string, std::uint16_t>> HostPort(const std::string& text) {
  const std::size_t colon = text.rfind(':');
  if (colon != std::string::npos && text.substr(colon + 1) == "0") {
    auto url = net::ParseWebSocketUrl(text.substr(0, colon) + ":1");
    if (!url.ok()) return url.status().WithPrefix("--listen");
    return std::make_pair(url->host, std::uint16_t{0});
  }
  auto url = net::ParseWebSocketUrl(text);
  if (!url.ok()) return url.status().WithPrefix("--listen");
  return std::make_pair(url->host, url->port);
}

struct Loaded {
  scene::Scene scene;
  robot::RobotModel model;
};

Result<Loaded> LoadSceneAndRobot(const std::string& scene_path) {
  auto scene = scene::LoadScene(scene_path);
  if (!scene.ok()) return scene.status();
  if (!scene->robot) return Status::InvalidInput(scene_path + ": robot: missing (the work site runs an arm)");
  auto model = robot::LoadRobotModel(DataPath("robots/" + scene->robot->model + ".json"));
  if (!model.ok()) return model.status();
  return Loaded{std::move(scene).value(), std::move(model).value()};
}

Result<worksite::WorksiteServiceOptions> WorksiteOptions(const SiteArgs& a, const net::Token& token) {
  worksite::WorksiteServiceOptions o;
  auto listen = HostPort(a.listen);
  if (!listen.ok()) return listen.status();
  o.server.host = listen->first;
  o.server.port = listen->second;
  o.server.name = "teachsim-worksite";
  o.server.token = token;
  o.server.link_timeout_s = a.link_timeout_s;
  if (a.error_mm > 0 || a.error_deg > 0) {
    worksite::ModelError error;
    error.position_m = a.error_mm * 1e-3;
    error.angle_rad = a.error_deg * M_PI / 180;
    error.seed = a.seed;
    o.model_error = error;
  }
  o.time_scale = a.time_scale;
  o.camera = a.camera;
  o.recognize = !a.no_recognition;
  // The recognizer's model-view index is cached as `teachsim demo` caches it.
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0') {
    o.recognizer_cache_dir = (std::filesystem::path(home) / ".cache" / "teachsim" / "recognizer").string();
  }
  return o;
}

op::OperatorOptions OperatorOptionsFrom(const SiteArgs& a, const std::string& worksite, const net::Token& token) {
  op::OperatorOptions o;
  o.http_port = static_cast<std::uint16_t>(a.http_port);
  o.web_root = WebRoot(a.web_root);
  o.sessions_dir = a.sessions;
  o.worksite = worksite;
  o.token = token;
  o.link_timeout_s = a.link_timeout_s;
  o.browser_link_timeout_s = a.browser_link_timeout_s;
  o.robots_dir = DataPath("robots");
  return o;
}

void PrintUrl(std::uint16_t port) {
  std::printf("teachsim: operator url http://127.0.0.1:%u/\n", static_cast<unsigned>(port));
  std::fflush(stdout);
}

int RunWorksite(const SiteArgs& a) {
  auto loaded = LoadSceneAndRobot(a.scene);
  if (!loaded.ok()) return ReportError(loaded.status());
  std::string token_file = a.token_file;
  if (token_file.empty()) {
    auto generated = GenerateTokenFile();
    if (!generated.ok()) return ReportError(generated.status());
    token_file = *generated;
    std::printf("teachsim: token file %s (give it to the operator site with --token-file)\n", token_file.c_str());
  }
  auto token = net::ReadTokenFile(token_file);
  if (!token.ok()) return ReportError(token.status());
  auto options = WorksiteOptions(a, *token);
  if (!options.ok()) return ReportError(options.status());
  const sigset_t signals = BlockStopSignals();
  net::SteadyClock clock;
  auto service = worksite::WorksiteService::Create(clock, loaded->scene, loaded->model, *options);
  if (!service.ok()) return ReportError(service.status());
  if (Status s = (*service)->Start(); !s.ok()) return ReportError(s);
  std::printf("teachsim: worksite listening on ws://%s:%u/ws\n", options->server.host.c_str(),
              static_cast<unsigned>((*service)->port()));
  std::fflush(stdout);
  if (Status s = WritePortFile(a.port_file, (*service)->port()); !s.ok()) return ReportError(s);
  WaitForStopSignal(signals);
  (*service)->Stop();
  return 0;
}

int RunOperator(const SiteArgs& a) {
  if (a.token_file.empty()) return ReportError(Status::InvalidInput("operator: --token-file is required (the work site's token)"));
  auto token = net::ReadTokenFile(a.token_file);
  if (!token.ok()) return ReportError(token.status());
  if (auto url = net::ParseWebSocketUrl(a.worksite); !url.ok()) return ReportError(url.status().WithPrefix("--worksite"));
  const sigset_t signals = BlockStopSignals();
  net::SteadyClock clock;
  auto service = op::OperatorService::Create(clock, OperatorOptionsFrom(a, a.worksite, *token));
  if (!service.ok()) return ReportError(service.status());
  if (Status s = (*service)->Start(); !s.ok()) return ReportError(s);
  PrintUrl((*service)->port());
  if (Status s = WritePortFile(a.port_file, (*service)->port()); !s.ok()) return ReportError(s);
  WaitForStopSignal(signals);
  (*service)->Stop();
  return 0;
}

int RunUp(SiteArgs a) {
  if (a.scene.empty()) a.scene = DataPath("scenes/puzzle.json");
  auto loaded = LoadSceneAndRobot(a.scene);
  if (!loaded.ok()) return ReportError(loaded.status());
  auto token_file = GenerateTokenFile();
  if (!token_file.ok()) return ReportError(token_file.status());
  auto token = net::ReadTokenFile(*token_file);
  if (!token.ok()) return ReportError(token.status());
  a.listen = "127.0.0.1:0";
  auto ws_options = WorksiteOptions(a, *token);
  if (!ws_options.ok()) return ReportError(ws_options.status());
  const sigset_t signals = BlockStopSignals();
  net::SteadyClock clock;
  auto site = worksite::WorksiteService::Create(clock, loaded->scene, loaded->model, *ws_options);
  if (!site.ok()) return ReportError(site.status());
  if (Status s = (*site)->Start(); !s.ok()) return ReportError(s);
  const std::string site_address = "127.0.0.1:" + std::to_string((*site)->port());
  auto op_service = op::OperatorService::Create(clock, OperatorOptionsFrom(a, site_address, *token));
  if (!op_service.ok()) return ReportError(op_service.status());
  if (Status s = (*op_service)->Start(); !s.ok()) return ReportError(s);
  std::printf("teachsim: worksite on ws://%s/ws (scene %s), token %s\n", site_address.c_str(), a.scene.c_str(),
              token_file->c_str());
  PrintUrl((*op_service)->port());
  if (Status s = WritePortFile(a.port_file, (*op_service)->port()); !s.ok()) return ReportError(s);
  WaitForStopSignal(signals);
  (*op_service)->Stop();
  (*site)->Stop();
  std::error_code ec;
  std::filesystem::remove_all(std::filesystem::path(*token_file).parent_path(), ec);
  return 0;
}

void AddCommonOptions(CLI::App* sub, SiteArgs* a) {
  sub->add_option("--port-file", a->port_file, "write the listening port to this file (for scripts and tests)");
  sub->add_option("--link-timeout", a->link_timeout_s,
                  "seconds of silence after which the work-site link counts as lost (the robot stops)")
      ->capture_default_str();
}

void AddWorldOptions(CLI::App* sub, SiteArgs* a) {
  sub->add_option("--model-error-mm", a->error_mm, "the work site's world: movable objects moved by up to this (mm)")
      ->capture_default_str();
  sub->add_option("--model-error-deg", a->error_deg, "... and turned by up to this (deg)")->capture_default_str();
  sub->add_option("--seed", a->seed, "seed of the model error and block friction")->capture_default_str();
  sub->add_option("--time-scale", a->time_scale, "simulated seconds per wall second while executing (0: unpaced)")
      ->capture_default_str();
  sub->add_option("--camera", a->camera, "scene camera to stream (default: the first)");
  sub->add_flag("--no-recognition", a->no_recognition, "do not run the recognizer on the camera images");
}

void AddOperatorOptions(CLI::App* sub, SiteArgs* a) {
  sub->add_option("--http-port", a->http_port, "browser port on 127.0.0.1 (0: a free one)")->capture_default_str();
  sub->add_option("--web-root", a->web_root, "folder of the browser UI (default: $TEACHSIM_HOME/web or the source tree's web/)");
  sub->add_option("--sessions", a->sessions, "folder of saved sessions")->capture_default_str();
  sub->add_option("--browser-link-timeout", a->browser_link_timeout_s,
                  "seconds of silence after which a browser counts as lost (its drag ends); browsers throttle "
                  "background tabs, so this is longer than --link-timeout")
      ->capture_default_str();
}

}  // namespace

void AddUpCommand(CLI::App& app, Runner* run) {
  {
    auto a = std::make_shared<SiteArgs>();
    CLI::App* sub = app.add_subcommand("up", "work site and operator site in one process over loopback; prints the URL");
    sub->add_option("--scene", a->scene, "scene (default: scenes/puzzle.json)");
    AddOperatorOptions(sub, a.get());
    AddWorldOptions(sub, a.get());
    AddCommonOptions(sub, a.get());
    sub->callback([a, run] { *run = [a] { return RunUp(*a); }; });
  }
  {
    auto a = std::make_shared<SiteArgs>();
    CLI::App* sub = app.add_subcommand("worksite", "the work-site service: MuJoCo world, camera, robot, programs");
    sub->add_option("--scene", a->scene, "scene (JSON) placing the robot")->required();
    sub->add_option("--listen", a->listen, "HOST:PORT to listen on")->capture_default_str();
    sub->add_option("--token-file", a->token_file, "shared secret of the link (default: generate one)");
    AddWorldOptions(sub, a.get());
    AddCommonOptions(sub, a.get());
    sub->callback([a, run] { *run = [a] { return RunWorksite(*a); }; });
  }
  {
    auto a = std::make_shared<SiteArgs>();
    CLI::App* sub = app.add_subcommand("operator", "the operator-site service: browser UI, simulator, planner");
    sub->add_option("--worksite", a->worksite, "the work site's HOST:PORT (or ws://HOST:PORT/PATH)")->required();
    sub->add_option("--token-file", a->token_file, "the work site's shared secret")->required();
    AddOperatorOptions(sub, a.get());
    AddCommonOptions(sub, a.get());
    sub->callback([a, run] { *run = [a] { return RunOperator(*a); }; });
  }
}

}  // namespace teachsim::app
