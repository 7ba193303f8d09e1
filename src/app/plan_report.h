// Shared by `teachsim plan` and `teachsim demo`.
#pragma once

#include <string>

#include "teachsim/plan/planner.h"

namespace teachsim::app {

void PrintPlanMetrics(const plan::PlanMetrics& metrics);
// The program, and with a non-empty prefix the initial, deformed and simplified paths.
[[nodiscard]] Status WritePlanOutputs(const plan::PlanResult& result, const std::string& program_file,
                                      const std::string& prefix);

}  // namespace teachsim::app
