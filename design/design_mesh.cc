#include "design/design_mesh.h"

#include <unistd.h>

#include <bit>
#include <cstdio>
#include <filesystem>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "design/step_reader.h"

namespace swarf::design {
namespace {

struct VertexKey {
  uint64_t x, y, z;
  bool operator==(const VertexKey&) const = default;
  template <typename H>
  friend H AbslHashValue(H h, const VertexKey& k) {
    return H::combine(std::move(h), k.x, k.y, k.z);
  }
};

// +0 and -0 weld to one vertex.
uint64_t Bits(double v) { return std::bit_cast<uint64_t>(v == 0 ? 0.0 : v); }

std::string Point(const Vec3& p) {
  return absl::StrFormat("(%.6g, %.6g, %.6g)", p.x, p.y, p.z);
}

absl::Status TooLarge(const std::string& name, int64_t n, int64_t max) {
  return absl::ResourceExhaustedError(absl::StrCat(
      name, ": the design has ", n, " triangles; at most ", max,
      " are accepted"));
}

float ReadFloat(const char* p) {
  float f;
  std::memcpy(&f, p, 4);
  return f;
}

absl::StatusOr<std::vector<double>> BinaryStlSoup(absl::string_view bytes,
                                                  const std::string& name,
                                                  uint32_t n,
                                                  const DesignReadOptions& o) {
  if (n > static_cast<uint64_t>(o.max_triangles)) {
    return TooLarge(name, n, o.max_triangles);
  }
  std::vector<double> soup;
  soup.reserve(size_t{n} * 9);
  const char* p = bytes.data() + 84;
  for (uint32_t t = 0; t < n; ++t, p += 50) {
    for (int k = 0; k < 3; ++k) {
      const char* v = p + 12 + 12 * k;
      soup.push_back(ReadFloat(v) * o.scale + o.offset.x);
      soup.push_back(ReadFloat(v + 4) * o.scale + o.offset.y);
      soup.push_back(ReadFloat(v + 8) * o.scale + o.offset.z);
    }
  }
  return soup;
}

// ASCII STL: "solid", then facets of "facet normal", "outer loop", three
// "vertex x y z", "endloop", "endfacet"; "endsolid". Several solids are
// read one after the other. Errors name the line.
absl::StatusOr<std::vector<double>> AsciiStlSoup(absl::string_view bytes,
                                                 const std::string& name,
                                                 const DesignReadOptions& o) {
  std::vector<double> soup;
  int64_t line_no = 0;
  int in_loop = -1;  // vertices read in the current loop, -1: outside one
  bool saw_solid = false;
  for (absl::string_view line : absl::StrSplit(bytes, '\n')) {
    ++line_no;
    line = absl::StripAsciiWhitespace(line);
    if (line.empty()) continue;
    std::vector<absl::string_view> w =
        absl::StrSplit(line, absl::ByAnyChar(" \t"), absl::SkipEmpty());
    auto bad = [&](absl::string_view what) {
      return absl::InvalidArgumentError(absl::StrCat(
          name, ": line ", line_no, ": ", what, ": \"", line.substr(0, 60),
          "\""));
    };
    const std::string key = absl::AsciiStrToLower(w[0]);
    if (key == "solid") {
      saw_solid = true;
    } else if (!saw_solid) {
      return bad("not an STL file (neither binary nor starting with \"solid\")");
    } else if (key == "facet" || key == "endsolid" || key == "endfacet") {
      if (in_loop >= 0) return bad("a loop is not closed");
    } else if (key == "outer") {
      in_loop = 0;
    } else if (key == "endloop") {
      if (in_loop != 3) return bad("a facet needs exactly 3 vertices");
      in_loop = -1;
    } else if (key == "vertex") {
      if (in_loop < 0 || in_loop >= 3) return bad("a vertex outside a loop");
      if (w.size() != 4) return bad("a vertex needs x y z");
      double v[3];
      for (int k = 0; k < 3; ++k) {
        if (!absl::SimpleAtod(w[k + 1], &v[k])) return bad("not a number");
        if (!std::isfinite(v[k])) return bad("not a finite coordinate");
      }
      soup.push_back(v[0] * o.scale + o.offset.x);
      soup.push_back(v[1] * o.scale + o.offset.y);
      soup.push_back(v[2] * o.scale + o.offset.z);
      ++in_loop;
      if (static_cast<int64_t>(soup.size() / 9) > o.max_triangles) {
        return TooLarge(name, static_cast<int64_t>(soup.size() / 9),
                        o.max_triangles);
      }
    } else {
      return bad("unknown STL keyword");
    }
  }
  if (!saw_solid) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": not an STL file (empty)"));
  }
  if (in_loop >= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": the file ends inside a facet"));
  }
  return soup;
}

bool IsStep(absl::string_view bytes) {
  return absl::StartsWith(
      absl::StripLeadingAsciiWhitespace(bytes.substr(0, 64)), "ISO-10303-21");
}

}  // namespace

absl::StatusOr<DesignMesh> MeshFromSoup(const std::vector<double>& soup,
                                        const std::string& name,
                                        int64_t max_triangles) {
  if (soup.size() % 9 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        name, ": ", soup.size(), " coordinates is not 9 per triangle"));
  }
  const int64_t n = static_cast<int64_t>(soup.size() / 9);
  if (n > max_triangles) return TooLarge(name, n, max_triangles);
  DesignMesh m;
  absl::flat_hash_map<VertexKey, int32_t> index;
  index.reserve(static_cast<size_t>(n) / 2 + 16);
  m.triangles.reserve(n);
  for (int64_t t = 0; t < n; ++t) {
    const double* c = &soup[t * 9];
    std::array<int32_t, 3> tri;
    for (int k = 0; k < 3; ++k) {
      const Vec3 p{c[3 * k], c[3 * k + 1], c[3 * k + 2]};
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
        return absl::InvalidArgumentError(absl::StrCat(
            name, ": triangle ", t + 1, " has a coordinate that is not a "
            "finite number"));
      }
      if (std::fabs(p.x) > kMaxDesignCoordinate ||
          std::fabs(p.y) > kMaxDesignCoordinate ||
          std::fabs(p.z) > kMaxDesignCoordinate) {
        return absl::InvalidArgumentError(absl::StrCat(
            name, ": triangle ", t + 1, " has a coordinate beyond +-",
            kMaxDesignCoordinate, " mm: ", Point(p)));
      }
      auto [it, added] = index.try_emplace(
          VertexKey{Bits(p.x), Bits(p.y), Bits(p.z)},
          static_cast<int32_t>(m.vertices.size()));
      if (added) {
        m.vertices.push_back(p);
        m.x.Hull({p.x, p.x});
        m.y.Hull({p.y, p.y});
        m.z.Hull({p.z, p.z});
      }
      tri[k] = it->second;
    }
    const Vec3& a = m.vertices[tri[0]];
    const Vec3& b = m.vertices[tri[1]];
    const Vec3& c2 = m.vertices[tri[2]];
    const double ux = b.x - a.x, uy = b.y - a.y, uz = b.z - a.z;
    const double vx = c2.x - a.x, vy = c2.y - a.y, vz = c2.z - a.z;
    const double nx = uy * vz - uz * vy, ny = uz * vx - ux * vz,
                 nz = ux * vy - uy * vx;
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] ||
        (nx == 0 && ny == 0 && nz == 0)) {
      ++m.degenerate_dropped;
      continue;
    }
    m.triangles.push_back(tri);
  }
  if (m.triangles.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        name, ": the design has no triangles",
        m.degenerate_dropped > 0
            ? absl::StrCat(" (", m.degenerate_dropped, " degenerate dropped)")
            : ""));
  }
  // Manifold: no edge is shared by more than two triangles. Open borders
  // (a design that is only the part's top surface) are allowed.
  absl::flat_hash_map<uint64_t, int32_t> edges;
  edges.reserve(m.triangles.size() * 3 / 2 + 16);
  for (const auto& t : m.triangles) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = static_cast<uint32_t>(t[k]);
      const uint32_t b = static_cast<uint32_t>(t[(k + 1) % 3]);
      const uint64_t key = (uint64_t{std::min(a, b)} << 32) | std::max(a, b);
      if (++edges[key] > 2) {
        return absl::InvalidArgumentError(absl::StrCat(
            name, ": non-manifold mesh: the edge ", Point(m.vertices[a]),
            " - ", Point(m.vertices[b]),
            " is shared by more than two triangles"));
      }
    }
  }
  m.closed = true;
  for (const auto& [key, count] : edges) m.closed &= count == 2;
  if (m.closed) {
    double volume6 = 0;  // six times the enclosed volume, signed
    for (const auto& t : m.triangles) {
      const Vec3& a = m.vertices[t[0]];
      const Vec3& b = m.vertices[t[1]];
      const Vec3& c = m.vertices[t[2]];
      volume6 += a.x * (b.y * c.z - b.z * c.y) - a.y * (b.x * c.z - b.z * c.x) +
                 a.z * (b.x * c.y - b.y * c.x);
    }
    m.outward = volume6 >= 0;
  }
  return m;
}

absl::StatusOr<DesignMesh> ParseStl(absl::string_view bytes,
                                    const std::string& name,
                                    const DesignReadOptions& options) {
  absl::StatusOr<std::vector<double>> soup;
  uint32_t n = 0;
  if (bytes.size() >= 84) std::memcpy(&n, bytes.data() + 80, 4);
  if (bytes.size() >= 84 && bytes.size() == 84 + uint64_t{50} * n) {
    soup = BinaryStlSoup(bytes, name, n, options);
  } else {
    const absl::string_view head = bytes.substr(0, 80);
    if (!absl::StartsWithIgnoreCase(absl::StripLeadingAsciiWhitespace(head),
                                    "solid")) {
      return absl::InvalidArgumentError(absl::StrCat(
          name, ": not an STL file: neither binary (", bytes.size(),
          " bytes is not 84 + 50 x ", n, " triangles) nor ASCII (\"solid\")"));
    }
    soup = AsciiStlSoup(bytes, name, options);
  }
  if (!soup.ok()) return soup.status();
  return MeshFromSoup(*soup, name, options.max_triangles);
}

absl::StatusOr<DesignMesh> ReadDesignFile(const std::string& path,
                                          const DesignReadOptions& options) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open ", path));
  std::ostringstream text;
  text << in.rdbuf();
  const std::string bytes = std::move(text).str();
  if (IsStep(bytes)) {
    auto soup = TessellateStep(path, options);
    if (!soup.ok()) return soup.status();
    return MeshFromSoup(*soup, path, options.max_triangles);
  }
  return ParseStl(bytes, path, options);
}

absl::StatusOr<DesignMesh> ParseDesign(absl::string_view bytes,
                                       const std::string& name,
                                       const DesignReadOptions& options) {
  if (!IsStep(bytes)) return ParseStl(bytes, name, options);
  std::string tmpl =
      (std::filesystem::temp_directory_path() / "swarf_design_XXXXXX.step")
          .string();
  const int fd = mkstemps(tmpl.data(), 5);
  if (fd < 0) {
    return absl::InternalError(
        absl::StrCat(name, ": cannot write a temporary STEP file"));
  }
  bool written = true;
  for (size_t done = 0; done < bytes.size();) {
    const ssize_t n = write(fd, bytes.data() + done, bytes.size() - done);
    if (n <= 0) {
      written = false;
      break;
    }
    done += static_cast<size_t>(n);
  }
  close(fd);
  absl::StatusOr<std::vector<double>> soup =
      written ? TessellateStep(tmpl, options, name)
              : absl::InternalError(absl::StrCat(
                    name, ": cannot write a temporary STEP file"));
  std::remove(tmpl.c_str());
  if (!soup.ok()) return soup.status();
  return MeshFromSoup(*soup, name, options.max_triangles);
}

std::string ToBinaryStl(const DesignMesh& mesh) {
  std::string out(80, ' ');
  out.replace(0, 18, "swarf design mesh ");
  const uint32_t n = static_cast<uint32_t>(mesh.triangles.size());
  out.append(reinterpret_cast<const char*>(&n), 4);
  for (const auto& t : mesh.triangles) {
    float f[12] = {0, 0, 0};
    for (int k = 0; k < 3; ++k) {
      const Vec3& p = mesh.vertices[t[k]];
      f[3 + 3 * k] = static_cast<float>(p.x);
      f[4 + 3 * k] = static_cast<float>(p.y);
      f[5 + 3 * k] = static_cast<float>(p.z);
    }
    out.append(reinterpret_cast<const char*>(f), sizeof(f));
    out.append(2, '\0');
  }
  return out;
}

}  // namespace swarf::design
