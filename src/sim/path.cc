#include "teachsim/sim/path.h"

#include <cmath>

namespace teachsim::sim {

using json::Json;
using json::Reader;

namespace {
Json Vec(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
}  // namespace

Json PathToJson(const WorkpiecePath& path) {
  Json nodes = Json::array();
  for (const PathNode& n : path.nodes) {
    Json contacts = Json::array();
    for (const PathContact& c : n.contacts) {
      contacts.push_back({{"object", c.object}, {"point", Vec(c.point)}, {"normal", Vec(c.normal)},
                          {"distance", c.distance}, {"capture", c.capture}});
    }
    Json node{{"time_s", n.time_s}, {"pose", geometry::WritePose(n.world_T_workpiece)}, {"contacts", contacts}};
    if (!n.captured.empty()) node["captured"] = n.captured;
    nodes.push_back(std::move(node));
  }
  return {{"format", "teachsim.path/1"},
          {"workpiece", path.workpiece},
          {"step_s", path.step_s},
          {"capture_objects", path.capture_objects},
          {"nodes", nodes}};
}

Result<WorkpiecePath> ParsePath(const Json& document, const std::string& name) {
  return json::Decode<WorkpiecePath>(document, name, [](const Reader& r) {
    r.RejectUnknownKeys({"format", "workpiece", "step_s", "capture_objects", "nodes"});
    if (r.Has("format") && r.At("format").String() != "teachsim.path/1") {
      r.At("format").Fail("unsupported format '" + r.At("format").String() + "' (expected teachsim.path/1)");
    }
    WorkpiecePath path;
    path.workpiece = r.At("workpiece").NonEmptyString();
    path.step_s = r.At("step_s").NumberGreaterThan(0.0);
    if (auto capture = r.Find("capture_objects")) {
      for (std::size_t i = 0; i < capture->Size(); ++i) path.capture_objects.push_back(capture->Index(i).NonEmptyString());
    }
    Reader nodes = r.At("nodes");
    if (nodes.Size() == 0) nodes.Fail("must have at least one node");
    double previous = -1e300;
    for (std::size_t i = 0; i < nodes.Size(); ++i) {
      Reader n = nodes.Index(i);
      n.RejectUnknownKeys({"time_s", "pose", "contacts", "captured"});
      PathNode node;
      node.time_s = n.At("time_s").Number();
      if (node.time_s < previous) n.At("time_s").Fail("must not decrease (previous node at " + json::FormatNumber(previous) + ")");
      previous = node.time_s;
      node.world_T_workpiece = geometry::ReadPose(n.At("pose"));
      Reader contacts = n.At("contacts");
      for (std::size_t k = 0; k < contacts.Size(); ++k) {
        Reader c = contacts.Index(k);
        c.RejectUnknownKeys({"object", "point", "normal", "distance", "capture"});
        PathContact pc;
        pc.object = c.At("object").NonEmptyString();
        pc.point = c.At("point").Vector3();
        pc.normal = c.At("normal").Vector3();
        if (std::abs(pc.normal.norm() - 1.0) > 1e-6) {
          c.At("normal").Fail("must be a unit vector, got norm " + json::FormatNumber(pc.normal.norm()));
        }
        pc.distance = c.At("distance").NumberAtLeast(0.0);
        pc.capture = c.At("capture").Bool();
        node.contacts.push_back(std::move(pc));
      }
      if (auto captured = n.Find("captured")) {
        for (std::size_t k = 0; k < captured->Size(); ++k) node.captured.push_back(captured->Index(k).NonEmptyString());
      }
      path.nodes.push_back(std::move(node));
    }
    return path;
  });
}

Result<WorkpiecePath> LoadPath(const std::string& file) {
  auto document = json::ReadFile(file);
  if (!document.ok()) return document.status();
  return ParsePath(*document, file);
}

Status SavePath(const WorkpiecePath& path, const std::string& file) {
  return json::WriteJsonFile(file, PathToJson(path));
}

}  // namespace teachsim::sim
