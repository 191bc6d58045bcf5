// Every output file of `swarf run --out DIR` from plain data: the fetched
// node grid, the error raster and the cutting marks.
#ifndef SWARF_CLIENT_RUN_OUTPUTS_H_
#define SWARF_CLIENT_RUN_OUTPUTS_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/outputs/grid_bands.h"
#include "client/outputs/pictures.h"
#include "client/outputs/surface_grid.h"
#include "client/outputs/surface_mesh.h"
#include "core/cutting_marks.h"

namespace swarf::cli {

struct RunOutputOptions {
  ReliefOptions relief;
  ErrorMapOptions error;
  MarksPictureOptions marks;
  SurfaceMeshOptions mesh;  // its tolerance > 0: the adaptive mesh
  bool vrml_colors = true;  // per-vertex height colours in surface.wrl
};

// A file written and how long it took to build and write (s).
struct WrittenFile {
  std::string path;
  double seconds = 0;
};

// The shown marks when they are not held (MarksStream): marks.svg and
// marks.json already written as they arrived, marks.png to draw from
// `source` (read twice).
struct StreamedMarks {
  // The shown marks as marks.png in `frame` strokes them (MarkKeeper).
  KeptMarkSource source;
  PixelFrame frame;
  std::vector<WrittenFile> files;  // marks.svg, marks.json as written
  // Their first write error (naming the file): returned where
  // WriteRunOutputs returns the marks files' errors.
  absl::Status status;
};

// What the meshes came to.
struct RunOutputSummary {
  int64_t mesh_triangles = 0;       // in surface.stl / surface.wrl
  int64_t full_mesh_triangles = 0;  // the full-resolution lattice's
  double mesh_deviation = 0;        // measured, mm (SimplifySurfaceMesh)
  // The pass over the grid's bands: wall time (s), of which reading the
  // bands (the rest is sampling: the pictures' pixels and the lattice,
  // counted in the files' times).
  double pass_seconds = 0, read_seconds = 0;
};

// Writes into the existing directory `dir`: relief.png; error.png when
// `error` is given; marks.png, marks.svg and marks.json when `marks` is
// given; surface.stl and surface.wrl; returned in that order. Three chains
// run at once (the pictures, the marks files, the meshes), each stopping at
// its first error; the first error in that order is returned (naming the
// file); files written stay. `summary`, if given, is filled when the meshes
// were written.
//
// The grid is read once, band by band (GridBands): each band gives the
// pictures' pixel rows over it and the mesh lattice's rows, then goes;
// memory is the pictures' (bounded by their sides) and the lattice's
// heights (8 bytes a lattice vertex), never a copy of the grid. The files
// are the same, byte for byte, whatever the bands.
absl::StatusOr<std::vector<WrittenFile>> WriteRunOutputs(
    const std::string& dir, GridBands& grid, const ErrorRaster* error,
    const std::vector<MarkPolyline>* marks,
    const RunOutputOptions& options = {}, RunOutputSummary* summary = nullptr);
// The same with the marks streamed: marks.png drawn from marks->source
// (a chunk of segments at a time, options.marks.chunk_segments; its frame
// must be marks.png's, ReliefFrame(spec, options.marks.relief), else
// InvalidArgument), marks.svg
// and marks.json as marks->files (in that place in the list) or
// marks->status. `marks` may be null (no marks files).
absl::StatusOr<std::vector<WrittenFile>> WriteRunOutputsStreamed(
    const std::string& dir, GridBands& grid, const ErrorRaster* error,
    const StreamedMarks* marks, const RunOutputOptions& options = {},
    RunOutputSummary* summary = nullptr);
// The same from a whole grid in memory (one band).
absl::StatusOr<std::vector<WrittenFile>> WriteRunOutputs(
    const std::string& dir, const SurfaceGrid& grid, const ErrorRaster* error,
    const std::vector<MarkPolyline>* marks,
    const RunOutputOptions& options = {}, RunOutputSummary* summary = nullptr);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_RUN_OUTPUTS_H_
