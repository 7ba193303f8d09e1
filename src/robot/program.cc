#include "teachsim/robot/program.h"

#include <Eigen/QR>
#include <cmath>
#include <cstdio>
#include <type_traits>

namespace teachsim::robot {

namespace {

constexpr double kUnitTolerance = 1e-6;

std::string Cmd(std::size_t i) { return "commands[" + std::to_string(i) + "]"; }

Status Bad(const std::string& path, const std::string& problem) {
  return Status::InvalidInput(path + ": " + problem);
}

Status CheckPositive(const std::string& path, double v) {
  if (!(std::isfinite(v) && v > 0))
    return Bad(path, "must be a finite number > 0, got " + json::FormatNumber(v));
  return Status::Ok();
}

Status CheckPose(const std::string& path, const geometry::Pose3& pose) {
  if (!pose.IsValid()) return Bad(path, "must be a finite pose with a unit quaternion");
  return Status::Ok();
}

template <class... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};
template <class... Ts>
Overloaded(Ts...) -> Overloaded<Ts...>;

json::Json Vec(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

std::string Mm(const Eigen::Vector3d& p) {
  char buffer[96];
  std::snprintf(buffer, sizeof buffer, "(%.1f, %.1f, %.1f) mm", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
  return buffer;
}

std::string Quat(const Eigen::Quaterniond& q) {
  char buffer[96];
  std::snprintf(buffer, sizeof buffer, "q_wxyz (%.3f, %.3f, %.3f, %.3f)", q.w(), q.x(), q.y(), q.z());
  return buffer;
}

}  // namespace

geometry::Pose3 GraspCommand::ApproachPose() const {
  return {world_T_tool.rotation, world_T_tool.translation + Eigen::Vector3d(0, 0, approach_height_m)};
}

geometry::Pose3 ContactMoveCommand::BiasedTarget() const {
  return {world_T_tool.rotation, world_T_tool.translation + bias_m};
}

const char* CommandType(const Command& command) {
  return std::visit(
      Overloaded{[](const GraspCommand&) { return "grasp"; }, [](const MoveCommand&) { return "move"; },
                 [](const ContactMoveCommand&) { return "contact_move"; },
                 [](const ReleaseCommand&) { return "release"; },
                 [](const RetreatCommand&) { return "retreat"; }},
      command);
}

Status Program::Validate() const {
  if (workpiece.empty()) return Bad("workpiece", "must name the scene object the program moves");
  TEACHSIM_RETURN_IF_ERROR(CheckPose("workpiece_T_tool", workpiece_T_tool));
  if (commands.empty()) return Bad("commands", "must hold at least one command");
  int holding_since = -1;  // index of the grasp that holds the workpiece, or -1
  for (std::size_t i = 0; i < commands.size(); ++i) {
    const std::string at = Cmd(i);
    Status s = std::visit(
        Overloaded{
            [&](const GraspCommand& c) -> Status {
              if (holding_since >= 0) {
                return Bad(at, "grasp while already holding the workpiece (grasped by " + Cmd(holding_since) +
                                   ", no release since)");
              }
              holding_since = static_cast<int>(i);
              TEACHSIM_RETURN_IF_ERROR(CheckPose(at + ".world_T_tool", c.world_T_tool));
              TEACHSIM_RETURN_IF_ERROR(CheckPositive(at + ".approach_height_m", c.approach_height_m));
              TEACHSIM_RETURN_IF_ERROR(CheckPositive(at + ".approach_speed_mps", c.approach_speed_mps));
              TEACHSIM_RETURN_IF_ERROR(CheckPositive(at + ".speed_mps", c.speed_mps));
              TEACHSIM_RETURN_IF_ERROR(CheckPositive(at + ".contact_force_n", c.contact_force_n));
              TEACHSIM_RETURN_IF_ERROR(CheckPositive(at + ".width_m", c.width_m));
              TEACHSIM_RETURN_IF_ERROR(CheckPositive(at + ".open_width_m", c.open_width_m));
              if (!(c.open_width_m > c.width_m)) {
                return Bad(at + ".open_width_m", "must exceed width_m " + json::FormatNumber(c.width_m) +
                                                     ", got " + json::FormatNumber(c.open_width_m));
              }
              return Status::Ok();
            },
            [&](const MoveCommand& c) -> Status {
              TEACHSIM_RETURN_IF_ERROR(CheckPose(at + ".world_T_tool", c.world_T_tool));
              return CheckPositive(at + ".speed_mps", c.speed_mps);
            },
            [&](const ContactMoveCommand& c) -> Status {
              if (holding_since < 0)
                return Bad(at, "contact_move without holding the workpiece (no grasp before)");
              TEACHSIM_RETURN_IF_ERROR(CheckPose(at + ".world_T_tool", c.world_T_tool));
              const long k = c.normals.cols();
              if (k == 0) return Bad(at + ".normals", "must hold at least one contact normal");
              for (long n = 0; n < k; ++n) {
                const std::string np = at + ".normals[" + std::to_string(n) + "]";
                Eigen::Vector3d v = c.normals.col(n);
                if (!v.allFinite()) return Bad(np, "must be finite");
                if (std::abs(v.norm() - 1) > kUnitTolerance) {
                  return Bad(np, "must be a unit vector, got norm " + json::FormatNumber(v.norm()));
                }
                for (long m = 0; m < n; ++m) {
                  if (v.dot(c.normals.col(m)) > 1 - 1e-9) {
                    return Bad(np, "repeats normals[" + std::to_string(m) + "]");
                  }
                }
              }
              if (static_cast<long>(c.force_thresholds_n.size()) != k) {
                return Bad(at + ".force_thresholds_n",
                           "must hold one threshold per normal: " + std::to_string(k) + " normals, " +
                               std::to_string(c.force_thresholds_n.size()) + " thresholds");
              }
              for (std::size_t n = 0; n < c.force_thresholds_n.size(); ++n) {
                TEACHSIM_RETURN_IF_ERROR(CheckPositive(at + ".force_thresholds_n[" + std::to_string(n) + "]",
                                                       c.force_thresholds_n[n]));
              }
              if (!c.bias_m.allFinite()) return Bad(at + ".bias_m", "must be finite");
              for (long n = 0; n < k; ++n) {
                double along = c.normals.col(n).dot(c.bias_m);
                if (!(along < 0)) {
                  return Bad(at + ".bias_m",
                             "must move the target into every contact, but normals[" + std::to_string(n) +
                                 "] . bias_m = " + json::FormatNumber(along) + " m is not < 0");
                }
              }
              TEACHSIM_RETURN_IF_ERROR(CheckPositive(at + ".stiffness_n_per_m", c.stiffness_n_per_m));
              TEACHSIM_RETURN_IF_ERROR(CheckPositive(at + ".damping_n_s_per_m", c.damping_n_s_per_m));
              return CheckPositive(at + ".speed_mps", c.speed_mps);
            },
            [&](const ReleaseCommand& c) -> Status {
              if (holding_since < 0)
                return Bad(at, "release without holding the workpiece (no grasp before)");
              holding_since = -1;
              return CheckPositive(at + ".width_m", c.width_m);
            },
            [&](const RetreatCommand& c) -> Status {
              TEACHSIM_RETURN_IF_ERROR(CheckPositive(at + ".distance_m", c.distance_m));
              return CheckPositive(at + ".speed_mps", c.speed_mps);
            }},
        commands[i]);
    TEACHSIM_RETURN_IF_ERROR(s);
  }
  return Status::Ok();
}

Result<Program> ParseProgram(const json::Json& document, const std::string& name) {
  auto parsed = json::Decode<Program>(document, name, [](const json::Reader& r) {
    r.RejectUnknownKeys({"format", "version", "units", "workpiece", "workpiece_T_tool", "commands"});
    if (r.At("format").String() != "teachsim-program") r.At("format").Fail("must be \"teachsim-program\"");
    if (r.At("version").Integer() != 1) r.At("version").Fail("must be 1 (the only version this build reads)");
    json::Reader units = r.At("units");
    units.RejectUnknownKeys({"length", "angle", "time", "force"});
    const std::pair<const char*, const char*> si[] = {
        {"length", "m"}, {"angle", "rad"}, {"time", "s"}, {"force", "N"}};
    for (const auto& [quantity, unit] : si) {
      if (units.At(quantity).String() != unit)
        units.At(quantity).Fail(std::string("must be \"") + unit + "\" (SI)");
    }
    Program p;
    p.workpiece = r.At("workpiece").NonEmptyString();
    p.workpiece_T_tool = geometry::ReadPose(r.At("workpiece_T_tool"));
    json::Reader commands = r.At("commands");
    for (std::size_t i = 0; i < commands.Size(); ++i) {
      json::Reader c = commands.Index(i);
      std::string type = c.At("type").String();
      if (type == "grasp") {
        c.RejectUnknownKeys({"type", "world_T_tool", "approach_height_m", "approach_speed_mps", "speed_mps",
                             "contact_force_n", "open_width_m", "width_m"});
        GraspCommand g;
        g.world_T_tool = geometry::ReadPose(c.At("world_T_tool"));
        g.approach_height_m = c.At("approach_height_m").Number();
        g.approach_speed_mps = c.At("approach_speed_mps").Number();
        g.speed_mps = c.At("speed_mps").Number();
        g.contact_force_n = c.At("contact_force_n").Number();
        g.open_width_m = c.At("open_width_m").Number();
        g.width_m = c.At("width_m").Number();
        p.commands.emplace_back(g);
      } else if (type == "move") {
        c.RejectUnknownKeys({"type", "world_T_tool", "speed_mps"});
        MoveCommand m;
        m.world_T_tool = geometry::ReadPose(c.At("world_T_tool"));
        m.speed_mps = c.At("speed_mps").Number();
        p.commands.emplace_back(m);
      } else if (type == "contact_move") {
        c.RejectUnknownKeys({"type", "world_T_tool", "normals", "force_thresholds_n", "bias_m",
                             "stiffness_n_per_m", "damping_n_s_per_m", "speed_mps"});
        ContactMoveCommand m;
        m.world_T_tool = geometry::ReadPose(c.At("world_T_tool"));
        json::Reader normals = c.At("normals");
        m.normals.resize(3, static_cast<long>(normals.Size()));
        for (std::size_t n = 0; n < normals.Size(); ++n)
          m.normals.col(static_cast<long>(n)) = normals.Index(n).Vector3();
        json::Reader thresholds = c.At("force_thresholds_n");
        for (std::size_t n = 0; n < thresholds.Size(); ++n)
          m.force_thresholds_n.push_back(thresholds.Index(n).Number());
        m.bias_m = c.At("bias_m").Vector3();
        m.stiffness_n_per_m = c.At("stiffness_n_per_m").Number();
        m.damping_n_s_per_m = c.At("damping_n_s_per_m").Number();
        m.speed_mps = c.At("speed_mps").Number();
        p.commands.emplace_back(m);
      } else if (type == "release") {
        c.RejectUnknownKeys({"type", "width_m"});
        p.commands.emplace_back(ReleaseCommand{c.At("width_m").Number()});
      } else if (type == "retreat") {
        c.RejectUnknownKeys({"type", "distance_m", "speed_mps"});
        p.commands.emplace_back(RetreatCommand{c.At("distance_m").Number(), c.At("speed_mps").Number()});
      } else {
        c.At("type").Fail("unknown command type '" + type +
                          "' (expected one of: grasp, move, contact_move, release, retreat)");
      }
    }
    return p;
  });
  if (!parsed.ok()) return parsed.status();
  if (Status s = parsed->Validate(); !s.ok()) return s.WithPrefix(name);
  return parsed;
}

Result<Program> LoadProgram(const std::string& path) {
  TEACHSIM_ASSIGN_OR_RETURN(json::Json document, json::ReadFile(path));
  return ParseProgram(document, path);
}

json::Json ProgramToJson(const Program& p) {
  json::Json commands = json::Json::array();
  for (const Command& command : p.commands) {
    json::Json c = std::visit(
        Overloaded{
            [](const GraspCommand& g) -> json::Json {
              return {{"world_T_tool", geometry::WritePose(g.world_T_tool)},
                      {"approach_height_m", g.approach_height_m},
                      {"approach_speed_mps", g.approach_speed_mps},
                      {"speed_mps", g.speed_mps},
                      {"contact_force_n", g.contact_force_n},
                      {"open_width_m", g.open_width_m},
                      {"width_m", g.width_m}};
            },
            [](const MoveCommand& m) -> json::Json {
              return {{"world_T_tool", geometry::WritePose(m.world_T_tool)}, {"speed_mps", m.speed_mps}};
            },
            [](const ContactMoveCommand& m) -> json::Json {
              json::Json normals = json::Json::array();
              for (long n = 0; n < m.normals.cols(); ++n) normals.push_back(Vec(m.normals.col(n)));
              return {{"world_T_tool", geometry::WritePose(m.world_T_tool)},
                      {"normals", normals},
                      {"force_thresholds_n", m.force_thresholds_n},
                      {"bias_m", Vec(m.bias_m)},
                      {"stiffness_n_per_m", m.stiffness_n_per_m},
                      {"damping_n_s_per_m", m.damping_n_s_per_m},
                      {"speed_mps", m.speed_mps}};
            },
            [](const ReleaseCommand& r) -> json::Json {
              return {{"width_m", r.width_m}};
            },
            [](const RetreatCommand& r) -> json::Json {
              return {{"distance_m", r.distance_m}, {"speed_mps", r.speed_mps}};
            }},
        command);
    c["type"] = CommandType(command);
    commands.push_back(std::move(c));
  }
  return {{"format", "teachsim-program"},
          {"version", 1},
          {"units", {{"length", "m"}, {"angle", "rad"}, {"time", "s"}, {"force", "N"}}},
          {"workpiece", p.workpiece},
          {"workpiece_T_tool", geometry::WritePose(p.workpiece_T_tool)},
          {"commands", commands}};
}

std::string ProgramToText(const Program& program) { return ProgramToJson(program).dump(2) + "\n"; }

Status SaveProgram(const Program& program, const std::string& path) {
  TEACHSIM_RETURN_IF_ERROR(program.Validate().WithPrefix(path));
  return json::WriteFileAtomic(path, ProgramToText(program));
}

std::string ProgramListing(const Program& p) {
  std::string out = "program for '" + p.workpiece + "', grasped with the tool at " +
                    Mm(p.workpiece_T_tool.translation) + " in the workpiece, " +
                    std::to_string(p.commands.size()) + " commands\n";
  char line[512];
  for (std::size_t i = 0; i < p.commands.size(); ++i) {
    std::string text = std::visit(
        Overloaded{
            [&](const GraspCommand& g) {
              std::snprintf(
                  line, sizeof line,
                  "at %s %s: approach %.1f mm above at %.1f mm/s, descend at %.1f mm/s, stop at %.1f N, "
                  "open %.1f mm, close to %.1f mm",
                  Mm(g.world_T_tool.translation).c_str(), Quat(g.world_T_tool.rotation).c_str(),
                  g.approach_height_m * 1e3, g.approach_speed_mps * 1e3, g.speed_mps * 1e3, g.contact_force_n,
                  g.open_width_m * 1e3, g.width_m * 1e3);
              return std::string(line);
            },
            [&](const MoveCommand& m) {
              std::snprintf(line, sizeof line, "to %s %s at %.1f mm/s",
                            Mm(m.world_T_tool.translation).c_str(), Quat(m.world_T_tool.rotation).c_str(),
                            m.speed_mps * 1e3);
              return std::string(line);
            },
            [&](const ContactMoveCommand& m) {
              std::snprintf(
                  line, sizeof line, "to %s %s at %.1f mm/s, bias %s, K %.0f N/m, B %.0f N s/m, contacts:",
                  Mm(m.world_T_tool.translation).c_str(), Quat(m.world_T_tool.rotation).c_str(),
                  m.speed_mps * 1e3, Mm(m.bias_m).c_str(), m.stiffness_n_per_m, m.damping_n_s_per_m);
              std::string s = line;
              for (long n = 0; n < m.normals.cols(); ++n) {
                std::snprintf(line, sizeof line, " n (%.3f, %.3f, %.3f) >= %.1f N", m.normals(0, n),
                              m.normals(1, n), m.normals(2, n),
                              m.force_thresholds_n[static_cast<std::size_t>(n)]);
                s += (n > 0 ? "," : "") + std::string(line);
              }
              return s;
            },
            [&](const ReleaseCommand& r) {
              std::snprintf(line, sizeof line, "open to %.1f mm", r.width_m * 1e3);
              return std::string(line);
            },
            [&](const RetreatCommand& r) {
              std::snprintf(line, sizeof line, "up %.1f mm at %.1f mm/s", r.distance_m * 1e3,
                            r.speed_mps * 1e3);
              return std::string(line);
            }},
        p.commands[i]);
    std::snprintf(line, sizeof line, "%3zu %-13s ", i, CommandType(p.commands[i]));
    out += line + text + "\n";
  }
  return out;
}

Result<Eigen::Vector3d> ContactBias(const Eigen::Matrix3Xd& normals, double depth_m, double max_norm_m) {
  const long k = normals.cols();
  if (k == 0) return Status::InvalidInput("contact bias: no contact normals");
  if (!(std::isfinite(depth_m) && depth_m > 0)) {
    return Status::InvalidInput("contact bias: depth must be > 0, got " + json::FormatNumber(depth_m));
  }
  for (long n = 0; n < k; ++n) {
    if (!normals.col(n).allFinite() || std::abs(normals.col(n).norm() - 1) > kUnitTolerance) {
      return Status::InvalidInput("contact bias: normal " + std::to_string(n) + " is not a unit vector");
    }
  }
  // Least-norm least-squares solution of N^T delta_p = -d 1 (complete orthogonal decomposition).
  const Eigen::MatrixXd A = normals.transpose();
  const Eigen::VectorXd b = Eigen::VectorXd::Constant(k, -depth_m);
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(A);
  cod.setThreshold(1e-12);
  const Eigen::Vector3d delta = cod.solve(b);
  const double residual = (A * delta - b).norm();
  if (!(residual <= 1e-9 * depth_m)) {
    for (long i = 0; i < k; ++i) {
      for (long j = i + 1; j < k; ++j) {
        if (normals.col(i).dot(normals.col(j)) < -1 + 1e-9) {
          return Status::InvalidInput(
              "contact bias: normals " + std::to_string(i) + " and " + std::to_string(j) +
              " oppose each other (a tight fit, paper §6.2): no bias moves into both");
        }
      }
    }
    return Status::InvalidInput("contact bias: no bias moves " + json::FormatNumber(depth_m * 1e3) +
                                " mm into all " + std::to_string(k) + " contacts (least-squares residual " +
                                json::FormatNumber(residual * 1e3) + " mm): a tight fit, paper §6.2");
  }
  if (!(delta.norm() <= max_norm_m)) {
    return Status::InvalidInput("contact bias: the bias needed is " + json::FormatNumber(delta.norm() * 1e3) +
                                " mm, above the limit " + json::FormatNumber(max_norm_m * 1e3) +
                                " mm (nearly opposing normals: a tight fit, paper §6.2)");
  }
  return delta;
}

}  // namespace teachsim::robot
