#include "teachsim/operator/session.h"

#include <algorithm>

namespace teachsim::op {

using json::Json;

namespace {

constexpr const char* kFormat = "teachsim-session";

Json OptionalPath(const std::optional<sim::WorkpiecePath>& path) {
  return path ? sim::PathToJson(*path) : Json(nullptr);
}

}  // namespace

Json SessionToJson(const SessionData& s) {
  Json doc = {{"format", kFormat},
              {"version", 1},
              {"scene", scene::SceneToJson(s.scene)},
              {"recognized", s.recognized},
              {"workpiece", s.workpiece ? Json(*s.workpiece) : Json(nullptr)},
              {"capture", s.capture},
              {"path", OptionalPath(s.path)},
              {"deformed", OptionalPath(s.deformed)},
              {"simplified", OptionalPath(s.simplified)},
              {"program", s.program ? robot::ProgramToJson(*s.program) : Json(nullptr)},
              {"program_id", s.program_id},
              {"report", nullptr}};
  if (s.report) doc["report"] = {{"program_id", s.report->program_id}, {"ok", s.report->ok}, {"report", s.report->report}};
  return doc;
}

Result<SessionData> ParseSession(const Json& document, const std::string& name) {
  // The envelope first (names checked against the scene below), then each part with its reader.
  struct Envelope {
    std::vector<std::string> recognized, capture;
    std::optional<std::string> workpiece;
    std::string program_id;
    std::optional<SessionReport> report;
  };
  auto envelope = json::Decode<Envelope>(document, name, [](const json::Reader& r) {
    r.RejectUnknownKeys({"format", "version", "scene", "recognized", "workpiece", "capture", "path", "deformed",
                         "simplified", "program", "program_id", "report"});
    if (r.At("format").String() != kFormat) r.At("format").Fail(std::string("must be \"") + kFormat + "\"");
    r.At("version").IntegerInRange(1, 1);
    if (!r.At("scene").IsObject()) r.At("scene").Fail("must be an object");
    Envelope e;
    auto names = [](const json::Reader& list) {
      std::vector<std::string> out;
      for (std::size_t i = 0; i < list.Size(); ++i) out.push_back(list.Index(i).NonEmptyString());
      return out;
    };
    e.recognized = names(r.At("recognized"));
    e.capture = names(r.At("capture"));
    if (!r.At("workpiece").IsNull()) e.workpiece = r.At("workpiece").NonEmptyString();
    e.program_id = r.At("program_id").String();
    for (const char* key : {"path", "deformed", "simplified", "program"}) {
      if (!r.At(key).IsNull() && !r.At(key).IsObject()) r.At(key).Fail("must be an object or null");
    }
    if (!r.At("report").IsNull()) {
      json::Reader rep = r.At("report");
      rep.RejectUnknownKeys({"program_id", "ok", "report"});
      SessionReport out;
      out.program_id = rep.At("program_id").String();
      out.ok = rep.At("ok").Bool();
      if (!rep.At("report").IsObject()) rep.At("report").Fail("must be an object");
      out.report = rep.At("report").raw();
      e.report = std::move(out);
    }
    return e;
  });
  if (!envelope.ok()) return envelope.status();

  SessionData s;
  auto scene = scene::ParseScene(document.at("scene"), name + ": scene");
  if (!scene.ok()) return scene.status();
  s.scene = std::move(scene).value();
  auto check_name = [&](const std::string& object, const std::string& field) -> Status {
    if (s.scene.FindObject(object) < 0) {
      return Status::InvalidInput(name + ": " + field + ": \"" + object + "\" is not an object of the scene");
    }
    return Status::Ok();
  };
  for (std::size_t i = 0; i < envelope->recognized.size(); ++i) {
    TEACHSIM_RETURN_IF_ERROR(check_name(envelope->recognized[i], "recognized[" + std::to_string(i) + "]"));
  }
  for (std::size_t i = 0; i < envelope->capture.size(); ++i) {
    TEACHSIM_RETURN_IF_ERROR(check_name(envelope->capture[i], "capture[" + std::to_string(i) + "]"));
  }
  if (envelope->workpiece) {
    TEACHSIM_RETURN_IF_ERROR(check_name(*envelope->workpiece, "workpiece"));
    if (s.scene.objects[static_cast<std::size_t>(s.scene.FindObject(*envelope->workpiece))].fixed) {
      return Status::InvalidInput(name + ": workpiece: \"" + *envelope->workpiece + "\" is fixed");
    }
  }
  s.recognized = envelope->recognized;
  s.capture = envelope->capture;
  s.workpiece = envelope->workpiece;
  s.program_id = envelope->program_id;
  s.report = envelope->report;
  auto read_path = [&](const char* key, std::optional<sim::WorkpiecePath>* out) -> Status {
    if (document.at(key).is_null()) return Status::Ok();
    auto path = sim::ParsePath(document.at(key), name + ": " + key);
    if (!path.ok()) return path.status();
    if (s.scene.FindObject(path->workpiece) < 0) {
      return Status::InvalidInput(name + ": " + key + ".workpiece: \"" + path->workpiece +
                                  "\" is not an object of the scene");
    }
    *out = std::move(path).value();
    return Status::Ok();
  };
  TEACHSIM_RETURN_IF_ERROR(read_path("path", &s.path));
  TEACHSIM_RETURN_IF_ERROR(read_path("deformed", &s.deformed));
  TEACHSIM_RETURN_IF_ERROR(read_path("simplified", &s.simplified));
  if (!document.at("program").is_null()) {
    auto program = robot::ParseProgram(document.at("program"), name + ": program");
    if (!program.ok()) return program.status();
    s.program = std::move(program).value();
  }
  return s;
}

Result<SessionData> LoadSession(const std::string& path) {
  auto document = json::ReadFile(path);
  if (!document.ok()) return document.status();
  return ParseSession(*document, path);
}

Status SaveSession(const SessionData& session, const std::string& path) {
  return json::WriteJsonFile(path, SessionToJson(session));
}

}  // namespace teachsim::op
