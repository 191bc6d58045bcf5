#include "design/closest_point.h"

#include <embree3/rtcore.h>

#include <cmath>
#include <vector>

#include "absl/strings/str_cat.h"

namespace swarf::design {
namespace {

double Dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
Vec3 Sub(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Vec3 Axpy(const Vec3& a, double s, const Vec3& d) {
  return {a.x + s * d.x, a.y + s * d.y, a.z + s * d.z};
}

struct QueryState {
  const DesignMesh* mesh;
  const int32_t* triangle_of;
  Vec3 p;
  double best2;  // squared distance of `best`
  Vec3 best;
  bool found = false;
};

bool PointQueryCallback(RTCPointQueryFunctionArguments* args) {
  auto* s = static_cast<QueryState*>(args->userPtr);
  const auto& tri = s->mesh->triangles[s->triangle_of[args->primID]];
  const Vec3 q = ClosestPointOnTriangle(s->p, s->mesh->vertices[tri[0]],
                                        s->mesh->vertices[tri[1]],
                                        s->mesh->vertices[tri[2]]);
  const Vec3 d = Sub(q, s->p);
  const double d2 = Dot(d, d);
  if (d2 < s->best2) {
    s->best2 = d2;
    s->best = q;
    s->found = true;
    // Shrink the search: Embree culls in float, so keep a small margin.
    args->query->radius = static_cast<float>(std::sqrt(d2) * (1 + 1e-6) + 1e-6);
    return true;
  }
  return false;
}

}  // namespace

Vec3 ClosestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b,
                            const Vec3& c) {
  const Vec3 ab = Sub(b, a), ac = Sub(c, a), ap = Sub(p, a);
  const double d1 = Dot(ab, ap), d2 = Dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = Sub(p, b);
  const double d3 = Dot(ab, bp), d4 = Dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return Axpy(a, d1 / (d1 - d3), ab);
  const Vec3 cp = Sub(p, c);
  const double d5 = Dot(ab, cp), d6 = Dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return Axpy(a, d2 / (d2 - d6), ac);
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    return Axpy(b, (d4 - d3) / ((d4 - d3) + (d5 - d6)), Sub(c, b));
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return Axpy(Axpy(a, v, ab), w, ac);
}

struct ClosestPointIndex::Embree {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  ~Embree() {
    if (scene != nullptr) rtcReleaseScene(scene);
    if (device != nullptr) rtcReleaseDevice(device);
  }
};

ClosestPointIndex::ClosestPointIndex(const DesignMesh& mesh)
    : mesh_(mesh), embree_(std::make_unique<Embree>()) {}

ClosestPointIndex::~ClosestPointIndex() = default;

absl::StatusOr<std::unique_ptr<ClosestPointIndex>> ClosestPointIndex::Build(
    const DesignMesh& mesh) {
  std::unique_ptr<ClosestPointIndex> index(new ClosestPointIndex(mesh));
  Embree& e = *index->embree_;
  e.device = rtcNewDevice(nullptr);
  if (e.device == nullptr) {
    return absl::InternalError(absl::StrCat(
        "Embree: cannot create a device (error ", rtcGetDeviceError(nullptr),
        ")"));
  }
  e.scene = rtcNewScene(e.device);
  // Downward faces of a solid are out of a 3-axis tool's reach.
  std::vector<int32_t>& keep = index->triangle_of_;
  keep.reserve(mesh.triangles.size());
  for (size_t k = 0; k < mesh.triangles.size(); ++k) {
    const auto& t = mesh.triangles[k];
    const Vec3& a = mesh.vertices[t[0]];
    const Vec3& b = mesh.vertices[t[1]];
    const Vec3& c = mesh.vertices[t[2]];
    const double nz = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
    const Vec3 ab = Sub(b, a), ac = Sub(c, a);
    const double area2 = std::hypot(ab.y * ac.z - ab.z * ac.y,
                                    ab.z * ac.x - ab.x * ac.z, nz);
    const double up = mesh.outward ? nz : -nz;
    if (mesh.closed && up < -1e-9 * area2) continue;
    keep.push_back(static_cast<int32_t>(k));
  }
  if (keep.empty()) {
    return absl::InvalidArgumentError(
        "the design has no surface that faces upwards");
  }
  RTCGeometry geom = rtcNewGeometry(e.device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
      mesh.vertices.size()));
  auto* ix = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
      keep.size()));
  if (v == nullptr || ix == nullptr) {
    rtcReleaseGeometry(geom);
    return absl::InternalError(absl::StrCat(
        "Embree: cannot allocate the design's buffers (error ",
        rtcGetDeviceError(e.device), ")"));
  }
  for (size_t k = 0; k < mesh.vertices.size(); ++k) {
    v[3 * k] = static_cast<float>(mesh.vertices[k].x);
    v[3 * k + 1] = static_cast<float>(mesh.vertices[k].y);
    v[3 * k + 2] = static_cast<float>(mesh.vertices[k].z);
  }
  for (size_t k = 0; k < keep.size(); ++k) {
    for (int c = 0; c < 3; ++c) ix[3 * k + c] = mesh.triangles[keep[k]][c];
  }
  rtcCommitGeometry(geom);
  rtcAttachGeometry(e.scene, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(e.scene);
  if (RTCError err = rtcGetDeviceError(e.device); err != RTC_ERROR_NONE) {
    return absl::InternalError(
        absl::StrCat("Embree: building the design's BVH failed (error ", err, ")"));
  }
  return index;
}

double ClosestPointIndex::Distance(const Vec3& p, double max_distance,
                                   Vec3* closest) const {
  QueryState s{&mesh_, triangle_of_.data(), p, max_distance * max_distance, {}, false};
  RTCPointQuery q;
  q.x = static_cast<float>(p.x);
  q.y = static_cast<float>(p.y);
  q.z = static_cast<float>(p.z);
  q.time = 0;
  // Float rounding of p and of the BVH's boxes: a margin, exact distances
  // are taken in double in the callback.
  q.radius = static_cast<float>(max_distance * (1 + 1e-6) + 1e-5);
  RTCPointQueryContext ctx;
  rtcInitPointQueryContext(&ctx);
  rtcPointQuery(embree_->scene, &q, &ctx, PointQueryCallback, &s);
  if (!s.found) return max_distance;
  if (closest != nullptr) *closest = s.best;
  return std::sqrt(s.best2);
}

}  // namespace swarf::design
