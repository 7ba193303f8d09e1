// The workpiece path (paper §6): one node per simulator step with the pose and the contacts.
// JSON I/O in docs/formats.md ("Workpiece path").
#pragma once

#include <string>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"

namespace teachsim::sim {

struct PathContact {
  std::string object;
  Eigen::Vector3d point;   // world, on the object
  Eigen::Vector3d normal;  // world, unit, from the object toward the workpiece
  double distance = 0.0;   // m
  bool capture = false;    // with an engaged capture object: a required-contact stretch
};

struct PathNode {
  double time_s = 0.0;
  geometry::Pose3 world_T_workpiece;
  std::vector<PathContact> contacts;
  std::vector<std::string> captured;  // capture objects engaged at this node (contact kept, maybe > eps_c)
};

struct WorkpiecePath {
  std::string workpiece;
  double step_s = 0.05;
  std::vector<std::string> capture_objects;  // every object that was a capture object at some time
  std::vector<PathNode> nodes;
};

json::Json PathToJson(const WorkpiecePath& path);
[[nodiscard]] Result<WorkpiecePath> ParsePath(const json::Json& document, const std::string& name);
[[nodiscard]] Result<WorkpiecePath> LoadPath(const std::string& file);
[[nodiscard]] Status SavePath(const WorkpiecePath& path, const std::string& file);  // atomic

}  // namespace teachsim::sim
