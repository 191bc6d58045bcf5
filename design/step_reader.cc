#include "design/step_reader.h"

#include <BRepMesh_IncrementalMesh.hxx>
#include <BRep_Tool.hxx>
#include <IFSelect_ReturnStatus.hxx>
#include <Poly_Triangulation.hxx>
#include <STEPControl_Reader.hxx>
#include <Standard_Failure.hxx>
#include <TopExp_Explorer.hxx>
#include <TopLoc_Location.hxx>
#include <TopoDS.hxx>
#include <TopoDS_Face.hxx>
#include <TopoDS_Shape.hxx>

#include "absl/strings/str_cat.h"

namespace swarf::design {

absl::StatusOr<std::vector<double>> TessellateStep(
    const std::string& path, const DesignReadOptions& options,
    const std::string& label) {
  const std::string& name = label.empty() ? path : label;
  try {
    STEPControl_Reader reader;
    if (reader.ReadFile(path.c_str()) != IFSelect_RetDone) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ": OpenCASCADE cannot read this STEP file"));
    }
    reader.TransferRoots();
    const TopoDS_Shape shape = reader.OneShape();
    if (shape.IsNull()) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ": the STEP file holds no shape"));
    }
    // The deflection is in the file's units (OpenCASCADE converts STEP's to
    // mm when it reads), so mm before `scale`.
    BRepMesh_IncrementalMesh mesher(
        shape, options.step_deflection / options.scale, false,
        options.step_angular_deflection, true);
    std::vector<double> soup;
    for (TopExp_Explorer ex(shape, TopAbs_FACE); ex.More(); ex.Next()) {
      const TopoDS_Face& face = TopoDS::Face(ex.Current());
      TopLoc_Location loc;
      const Handle(Poly_Triangulation) tri = BRep_Tool::Triangulation(face, loc);
      if (tri.IsNull()) continue;
      const gp_Trsf trsf = loc.Transformation();
      const bool reversed = face.Orientation() == TopAbs_REVERSED;
      for (Standard_Integer t = 1; t <= tri->NbTriangles(); ++t) {
        Standard_Integer n[3];
        tri->Triangle(t).Get(n[0], n[1], n[2]);
        if (reversed) std::swap(n[1], n[2]);
        if (static_cast<int64_t>(soup.size() / 9) >= options.max_triangles) {
          return absl::ResourceExhaustedError(absl::StrCat(
              name, ": the tessellated design has more than ",
              options.max_triangles, " triangles"));
        }
        for (int k = 0; k < 3; ++k) {
          const gp_Pnt p = tri->Node(n[k]).Transformed(trsf);
          soup.push_back(p.X() * options.scale + options.offset.x);
          soup.push_back(p.Y() * options.scale + options.offset.y);
          soup.push_back(p.Z() * options.scale + options.offset.z);
        }
      }
    }
    if (soup.empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ": the STEP file has no faces to tessellate"));
    }
    return soup;
  } catch (const Standard_Failure& e) {
    return absl::InvalidArgumentError(absl::StrCat(
        name, ": OpenCASCADE failed: ", e.GetMessageString()));
  }
}

}  // namespace swarf::design
