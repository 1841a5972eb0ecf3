// Flow-scheduled SVF variants of order 1 (design.md 1.5) behind the SvfEstimator classes:
// unit with 1..8 weights, affine and the hysteresis split with one (svf_handle.hpp).
#include <memory>

#include "svf_handle.hpp"

namespace dualprobe_bindings {
namespace svf {

namespace {

template <typename S, int K>
using Unit = dualprobe::SvfEstimator<S, 1, dualprobe::StaticModel::unit, false, 128, double, K>;

}  // namespace

template <typename S>
std::unique_ptr<Handle<S>> make_scheduled_order1(const Options& o) {
  using dualprobe::StaticModel;
  const bool affine = o.static_model == "affine";
  if (o.hysteresis) {
    if (affine) {
      return make_model<dualprobe::SvfEstimator<S, 1, StaticModel::affine, true, kMaxHalfWindow,
                                                double, 1>,
                        S>(o);
    }
    return make_model<
        dualprobe::SvfEstimator<S, 1, StaticModel::unit, true, kMaxHalfWindow, double, 1>, S>(o);
  }
  if (affine) return make_model<dualprobe::SvfScheduled<S, 1, 1, StaticModel::affine>, S>(o);
  switch (o.basis) {
    case 1: return make_model<Unit<S, 1>, S>(o);
    case 2: return make_model<Unit<S, 2>, S>(o);
    case 3: return make_model<Unit<S, 3>, S>(o);
    case 4: return make_model<Unit<S, 4>, S>(o);
    case 5: return make_model<Unit<S, 5>, S>(o);
    case 6: return make_model<Unit<S, 6>, S>(o);
    case 7: return make_model<Unit<S, 7>, S>(o);
    default: return make_model<Unit<S, 8>, S>(o);
  }
}

template std::unique_ptr<Handle<double>> make_scheduled_order1<double>(const Options&);
template std::unique_ptr<Handle<float>> make_scheduled_order1<float>(const Options&);

}  // namespace svf
}  // namespace dualprobe_bindings
