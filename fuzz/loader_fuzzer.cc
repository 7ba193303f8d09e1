// libFuzzer harnesses for the file loaders (issue 8, "Fuzzing"): scene, drag script, workpiece
// path, robot program, camera, robot table, calibration points, model library, operator session.
// One source, compiled once and linked into one executable per loader, each of which defines
// teachsim_fuzz_loader (its loader's name; fuzz/CMakeLists.txt generates that one line).
//
// Each input is what a file might hold. It must give a value or an error (InvalidInput naming the
// input), never a crash, a hang or a sanitizer report; and whatever loads must write out and load
// back to the same document (the loaders and writers agree).
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <string_view>

#include "teachsim/base/json.h"
#include "teachsim/operator/session.h"
#include "teachsim/robot/program.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/scene/scene.h"
#include "teachsim/sim/path.h"
#include "teachsim/sim/script.h"
#include "teachsim/vision/calibration.h"
#include "teachsim/vision/recognizer.h"

extern "C" const char teachsim_fuzz_loader[];

namespace {

using teachsim::Result;
using teachsim::Status;
using teachsim::json::Json;

[[noreturn]] void Broken(const char* what, const std::string& detail) {
  std::fprintf(stderr, "loader fuzzer (%s): %s: %s\n", teachsim_fuzz_loader, what, detail.c_str());
  std::abort();
}

// A refusal must be an InvalidInput that names the input (the file name stands in here).
void CheckRefusal(const Status& status) {
  if (status.ok()) return;
  if (status.message().find("input") == std::string::npos) Broken("error does not name the input", status.message());
}

// Loaded values must write out and load back to the same document.
template <typename T, typename Parse, typename Write>
void RoundTrip(const Result<T>& loaded, Parse parse, Write write) {
  CheckRefusal(loaded.status());
  if (!loaded.ok()) return;
  const Json once = write(*loaded);
  Result<T> again = parse(once);
  if (!again.ok()) Broken("written value does not load again", again.status().message());
  const Json twice = write(*again);
  if (once != twice) Broken("load -> write -> load -> write differs", once.dump().substr(0, 400));
}

// For loaders that only take a path: a file per process, rewritten per input.
std::string ScratchFile(std::string_view bytes) {
  static const std::string path = "/tmp/teachsim-loader-fuzz-" + std::to_string(::getpid()) + ".json";
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return path;
}

void Run(std::string_view bytes) {
  using namespace teachsim;
  const std::string loader = teachsim_fuzz_loader;
  if (loader == "models") {
    // LoadModels reads a file (a scene or {"models": [...]}).
    Result<vision::ModelLibrary> models = vision::LoadModels(ScratchFile(bytes));
    if (!models.ok() && models.status().message().find("teachsim-loader-fuzz") == std::string::npos) {
      Broken("error does not name the file", models.status().message());
    }
    return;
  }
  Result<Json> document = json::ParseText(bytes, "input");
  CheckRefusal(document.status());
  if (!document.ok()) return;
  const Json& doc = *document;
  if (loader == "scene") {
    RoundTrip(scene::ParseScene(doc, "input"), [](const Json& j) { return scene::ParseScene(j, "input"); },
              [](const scene::Scene& s) { return scene::SceneToJson(s); });
  } else if (loader == "script") {
    RoundTrip(sim::ParseScript(doc, "input"), [](const Json& j) { return sim::ParseScript(j, "input"); },
              [](const sim::DragScript& s) { return sim::ScriptToJson(s); });
  } else if (loader == "path") {
    RoundTrip(sim::ParsePath(doc, "input"), [](const Json& j) { return sim::ParsePath(j, "input"); },
              [](const sim::WorkpiecePath& p) { return sim::PathToJson(p); });
  } else if (loader == "program") {
    RoundTrip(robot::ParseProgram(doc, "input"), [](const Json& j) { return robot::ParseProgram(j, "input"); },
              [](const robot::Program& p) { return robot::ProgramToJson(p); });
  } else if (loader == "camera") {
    auto parse = [](const Json& j) {
      return json::Decode<scene::CameraSpec>(j, "input", [](const json::Reader& r) { return scene::ReadCamera(r); });
    };
    RoundTrip(parse(doc), parse, [](const scene::CameraSpec& c) { return scene::WriteCamera(c); });
  } else if (loader == "robot") {
    CheckRefusal(robot::ParseRobotModel(doc, "input").status());
  } else if (loader == "points") {
    CheckRefusal(vision::ParsePointCorrespondences(doc, "input").status());
  } else if (loader == "session") {
    RoundTrip(op::ParseSession(doc, "input"), [](const Json& j) { return op::ParseSession(j, "input"); },
              [](const op::SessionData& s) { return op::SessionToJson(s); });
  } else {
    Broken("unknown loader", loader);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Run(std::string_view(reinterpret_cast<const char*>(data), size));
  return 0;
}
