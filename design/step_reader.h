// STEP (ISO 10303-21) designs through OpenCASCADE: every face of the file's
// shapes tessellated (BRepMesh_IncrementalMesh) into a triangle soup.
#ifndef SWARF_DESIGN_STEP_READER_H_
#define SWARF_DESIGN_STEP_READER_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "design/design_mesh.h"

namespace swarf::design {

// 9 doubles a triangle, in mm (options.scale and offset applied), each
// face's triangles turned to face outwards. The linear deflection is
// options.step_deflection in mm: the tessellation lies within it of the
// exact surfaces. InvalidArgument naming the file when OpenCASCADE cannot
// read it or it holds no faces.
// Messages name `name` (default: the path).
absl::StatusOr<std::vector<double>> TessellateStep(
    const std::string& path, const DesignReadOptions& options,
    const std::string& name = "");

}  // namespace swarf::design

#endif  // SWARF_DESIGN_STEP_READER_H_
