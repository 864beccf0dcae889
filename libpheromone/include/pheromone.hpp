// pheromone.hpp: a header-only C++17 wrapper of pheromone.h (libpheromone). See docs/c-abi.md.
//
// - pheromone::Field owns a handle (attach in the constructor, detach in the destructor);
// - pheromone::Frame is a borrowed frame (released in its destructor); its planes are
//   pheromone::Span<const float> (std::span in C++20) into shared memory, no copy;
// - a failed call throws pheromone::Error (status + the library's message). A wait that times
//   out is not an error: Field::wait_frame returns false. Exceptions rather than an
//   expected-style result because C++17 has no std::expected, ROS 2's rclcpp reports errors by
//   exceptions too, and every error here is either a setup error (no field, other layout) or
//   bad input, not a value of the hot path, which costs nothing while nothing throws;
// - every throwing call has a `try_` twin that returns the PheromoneStatus instead and never
//   throws (Field::attach, try_wait_frame, try_borrow, Frame::try_value…). Built with
//   -fno-exceptions, the header leaves the throwing calls out and keeps the `try_` ones;
// - a Field lends one Frame at a time: a second borrow while a Frame lives is refused
//   (PHEROMONE_STATUS_BORROWED), as is a wait. A Frame shares the handle with its Field: it may
//   outlive the Field (the handle is detached when the last of them goes).
//
// Thread safety: as pheromone.h — a Field (and its Frame) is used by one thread at a time.
#ifndef PHEROMONE_HPP
#define PHEROMONE_HPP

#include <chrono>
#include <cstddef>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "pheromone.h"

#if defined(__cpp_exceptions) || defined(__EXCEPTIONS)
#define PHEROMONE_HPP_EXCEPTIONS 1
#include <stdexcept>
#else
#define PHEROMONE_HPP_EXCEPTIONS 0
#endif

#if __cplusplus >= 202002L && __has_include(<span>)
#include <span>
#endif

namespace pheromone {

#if __cplusplus >= 202002L && __has_include(<span>) && defined(__cpp_lib_span)
template <class T>
using Span = std::span<T>;
#else
/// A minimal std::span (C++17): a pointer and a length, no ownership.
template <class T>
class Span {
 public:
  constexpr Span() noexcept = default;
  constexpr Span(T* data, std::size_t size) noexcept : data_(data), size_(size) {}
  constexpr T* data() const noexcept { return data_; }
  constexpr std::size_t size() const noexcept { return size_; }
  constexpr bool empty() const noexcept { return size_ == 0; }
  constexpr T& operator[](std::size_t i) const noexcept { return data_[i]; }
  constexpr T* begin() const noexcept { return data_; }
  constexpr T* end() const noexcept { return data_ + size_; }

 private:
  T* data_ = nullptr;
  std::size_t size_ = 0;
};
#endif

/// The name of a status, e.g. "PHEROMONE_STATUS_NO_FIELD".
inline const char* status_name(PheromoneStatus s) noexcept {
  switch (s) {
    case PHEROMONE_STATUS_OK: return "PHEROMONE_STATUS_OK";
    case PHEROMONE_STATUS_TIMEOUT: return "PHEROMONE_STATUS_TIMEOUT";
    case PHEROMONE_STATUS_NO_FIELD: return "PHEROMONE_STATUS_NO_FIELD";
    case PHEROMONE_STATUS_BAD_ARGUMENT: return "PHEROMONE_STATUS_BAD_ARGUMENT";
    case PHEROMONE_STATUS_LAYOUT: return "PHEROMONE_STATUS_LAYOUT";
    case PHEROMONE_STATUS_NO_FRAME: return "PHEROMONE_STATUS_NO_FRAME";
    case PHEROMONE_STATUS_BORROWED: return "PHEROMONE_STATUS_BORROWED";
    case PHEROMONE_STATUS_NOT_DELIVERED: return "PHEROMONE_STATUS_NOT_DELIVERED";
    case PHEROMONE_STATUS_SHM_ERROR: return "PHEROMONE_STATUS_SHM_ERROR";
    case PHEROMONE_STATUS_INTERNAL: return "PHEROMONE_STATUS_INTERNAL";
    case PHEROMONE_STATUS_REJECTED: return "PHEROMONE_STATUS_REJECTED";
    case PHEROMONE_STATUS_INTERRUPTED: return "PHEROMONE_STATUS_INTERRUPTED";
    case PHEROMONE_STATUS_FIELD_DEAD: return "PHEROMONE_STATUS_FIELD_DEAD";
  }
  return "PHEROMONE_STATUS_?";
}

#if PHEROMONE_HPP_EXCEPTIONS
/// A failed call: its status and the library's message.
class Error : public std::runtime_error {
 public:
  Error(PheromoneStatus status, const char* message)
      : std::runtime_error(std::string(status_name(status)) + ": " + message), status_(status) {}
  PheromoneStatus status() const noexcept { return status_; }

 private:
  PheromoneStatus status_;
};

/// Throws `Error` unless `s` is OK.
inline void check(PheromoneStatus s) {
  if (s != PHEROMONE_STATUS_OK) throw Error(s, pheromone_last_error());
}
#endif

/// How Field::wait_frame waits.
struct Wait {
  static PheromoneWaitPolicy event() noexcept { return {PHEROMONE_WAIT_EVENT, 0}; }
  static PheromoneWaitPolicy spin(std::chrono::nanoseconds spin) noexcept {
    return {PHEROMONE_WAIT_SPIN, static_cast<uint64_t>(spin.count())};
  }
  static PheromoneWaitPolicy busy_poll() noexcept { return {PHEROMONE_WAIT_BUSY_POLL, 0}; }
};

/// The attach options' defaults (this header's layout version, deposits on).
inline PheromoneAttachOptions default_options() noexcept {
  PheromoneAttachOptions o;
  // Cannot fail: the pointer is valid.
  pheromone_attach_options_init(&o);
  return o;
}

/// The Rust depositor's defaults for seed 000's ellipse deposit.
inline PheromoneEllipseParams default_ellipse_params() noexcept {
  PheromoneEllipseParams p;
  // Cannot fail: the pointer is valid.
  pheromone_ellipse_params_init(&p);
  return p;
}

namespace detail {
/// The handle a Field and its Frame share: detached when the last of them goes.
struct Shared {
  PheromoneField* handle = nullptr;
  bool borrowed = false;
  Shared() = default;
  Shared(const Shared&) = delete;
  Shared& operator=(const Shared&) = delete;
  ~Shared() {
    if (borrowed) pheromone_frame_release(handle);
    pheromone_field_detach(handle);
  }
};
}  // namespace detail

class Field;

/// A borrowed frame: valid (not freed, not overwritten) until destroyed. Move-only; keeps the
/// handle it was borrowed from alive.
class Frame {
 public:
  /// An empty Frame (what Field::try_borrow fills).
  Frame() noexcept = default;
  Frame(Frame&& o) noexcept : shared_(std::move(o.shared_)), view_(o.view_) {}
  Frame& operator=(Frame&& o) noexcept {
    if (this != &o) {
      release();
      shared_ = std::move(o.shared_);
      view_ = o.view_;
    }
    return *this;
  }
  Frame(const Frame&) = delete;
  Frame& operator=(const Frame&) = delete;
  ~Frame() { release(); }

  /// Whether this Frame holds a borrowed frame (false when empty or moved from).
  explicit operator bool() const noexcept { return shared_ != nullptr; }
  const PheromoneFrameView& view() const noexcept { return view_; }
  uint64_t sequence() const noexcept { return view_.sequence; }
  uint64_t stamp_ns() const noexcept { return view_.stamp_ns; }
  double sim_time_s() const noexcept { return view_.sim_time_s; }
  uint32_t channels() const noexcept { return view_.channels; }
  uint32_t width() const noexcept { return view_.width; }
  uint32_t height() const noexcept { return view_.height; }
  float cell_size_m() const noexcept { return view_.cell_size_m; }

  /// Channel `c`'s cells in shared memory, row-major from the lower-left cell; empty for a
  /// channel the frame does not have.
  Span<const float> try_plane(uint32_t c) const noexcept {
    if (c >= view_.channels || !shared_) return Span<const float>();
    return Span<const float>(view_.planes[c], view_.plane_len);
  }

  /// Rust's FrameView::value into `out`.
  PheromoneStatus try_value(uint32_t channel, float x_m, float y_m, float& out) const noexcept {
    return pheromone_sample_value(handle(), channel, x_m, y_m, &out);
  }

  /// Rust's FrameView::gradient: (∂P/∂x, ∂P/∂y) per metre into `gx`, `gy`.
  PheromoneStatus try_gradient(uint32_t channel, float x_m, float y_m, float& gx,
                               float& gy) const noexcept {
    return pheromone_sample_gradient(handle(), channel, x_m, y_m, &gx, &gy);
  }

  /// pheromone_sample_many: `n` points `xy` (x0, y0, x1, y1, …) into `values` (n floats, or
  /// nullptr) and `gradients` (2n floats, or nullptr).
  PheromoneStatus try_sample_many(uint32_t channel, const float* xy, std::size_t n, float* values,
                                  float* gradients) const noexcept {
    return pheromone_sample_many(handle(), channel, xy, n, values, gradients);
  }

  /// Rust's FrameView::antennas into (`left`, `right`).
  PheromoneStatus try_antennas(uint32_t channel, PheromonePose pose, float wheel_base_m,
                               float& left, float& right) const noexcept {
    return pheromone_sample_antennas(handle(), channel, pose, wheel_base_m, &left, &right);
  }

  /// Rust's FrameView::sector_means into `out` (size ≥ 2·half_sectors + 1), no allocation.
  PheromoneStatus try_sectors(uint32_t channel, PheromonePose pose, float radius_m,
                              uint32_t half_sectors, Span<float> out) const noexcept {
    return pheromone_sample_sectors(handle(), channel, pose, radius_m, half_sectors, out.data(),
                                    out.size());
  }

#if PHEROMONE_HPP_EXCEPTIONS
  /// Channel `c`'s cells in shared memory, row-major from the lower-left cell.
  Span<const float> plane(uint32_t c) const {
    if (!shared_) throw Error(PHEROMONE_STATUS_NO_FRAME, "this Frame is empty or was moved from");
    if (c >= view_.channels) check_channel(c);
    return Span<const float>(view_.planes[c], view_.plane_len);
  }

  /// Rust's FrameView::value.
  float value(uint32_t channel, float x_m, float y_m) const {
    float v = 0.0f;
    check(try_value(channel, x_m, y_m, v));
    return v;
  }

  /// Rust's FrameView::gradient: (∂P/∂x, ∂P/∂y) per metre.
  std::pair<float, float> gradient(uint32_t channel, float x_m, float y_m) const {
    std::pair<float, float> g{0.0f, 0.0f};
    check(try_gradient(channel, x_m, y_m, g.first, g.second));
    return g;
  }

  /// Values (and gradients, when `gradients` is not null: 2 per point) at `xy.size() / 2`
  /// points in one call.
  std::vector<float> sample_many(uint32_t channel, const std::vector<float>& xy,
                                 std::vector<float>* gradients = nullptr) const {
    std::vector<float> values(xy.size() / 2);
    if (gradients != nullptr) gradients->assign(xy.size() / 2 * 2, 0.0f);
    check(try_sample_many(channel, xy.data(), values.size(), values.data(),
                          gradients != nullptr ? gradients->data() : nullptr));
    return values;
  }

  /// Rust's FrameView::antennas: (left, right).
  std::pair<float, float> antennas(uint32_t channel, PheromonePose pose, float wheel_base_m) const {
    std::pair<float, float> a{0.0f, 0.0f};
    check(try_antennas(channel, pose, wheel_base_m, a.first, a.second));
    return a;
  }

  /// Rust's FrameView::sector_means into `out` (size ≥ 2·half_sectors + 1), no allocation.
  void sectors(uint32_t channel, PheromonePose pose, float radius_m, uint32_t half_sectors,
               Span<float> out) const {
    check(try_sectors(channel, pose, radius_m, half_sectors, out));
  }

  /// As above, into a new vector.
  std::vector<float> sectors(uint32_t channel, PheromonePose pose, float radius_m,
                             uint32_t half_sectors) const {
    std::vector<float> out(2 * static_cast<std::size_t>(half_sectors) + 1);
    sectors(channel, pose, radius_m, half_sectors, Span<float>(out.data(), out.size()));
    return out;
  }
#endif

 private:
  friend class Field;
  Frame(std::shared_ptr<detail::Shared> shared, const PheromoneFrameView& view) noexcept
      : shared_(std::move(shared)), view_(view) {}
  /// NULL for an empty Frame: the library then refuses the call (BAD_ARGUMENT, "field is NULL").
  const PheromoneField* handle() const noexcept { return shared_ ? shared_->handle : nullptr; }
#if PHEROMONE_HPP_EXCEPTIONS
  void check_channel(uint32_t c) const {
    throw Error(PHEROMONE_STATUS_BAD_ARGUMENT,
                ("channel = " + std::to_string(c) + ": the frame has " +
                 std::to_string(view_.channels) + " channel(s)")
                    .c_str());
  }
#endif
  void release() noexcept {
    if (!shared_) return;
    pheromone_frame_release(shared_->handle);
    shared_->borrowed = false;
    shared_.reset();
  }

  std::shared_ptr<detail::Shared> shared_;
  PheromoneFrameView view_{};
};

/// An attachment to a running field. Move-only; detaches when destroyed and no Frame of it
/// lives any more.
class Field {
 public:
  /// An empty Field (what Field::attach fills).
  Field() noexcept = default;

  /// Attaches to field `name` into `out`, nothing thrown: PHEROMONE_STATUS_OK, or the failure
  /// (pheromone_last_error() says why; `out` then stays empty).
  static PheromoneStatus attach(const char* name, const PheromoneAttachOptions& options,
                                Field& out) noexcept {
    PheromoneField* h = nullptr;
    PheromoneStatus s = pheromone_field_attach(name, &options, &h);
    if (s != PHEROMONE_STATUS_OK) return s;
    out = Field(h);
    return out.shared_ ? PHEROMONE_STATUS_OK : PHEROMONE_STATUS_INTERNAL;
  }

#if PHEROMONE_HPP_EXCEPTIONS
  /// Attaches to field `name` (throws Error: PHEROMONE_STATUS_NO_FIELD, _LAYOUT, …).
  explicit Field(const std::string& name, const PheromoneAttachOptions& options = default_options()) {
    check(attach(name.c_str(), options, *this));
  }
#endif
  Field(Field&& o) noexcept = default;
  Field& operator=(Field&& o) noexcept = default;
  Field(const Field&) = delete;
  Field& operator=(const Field&) = delete;
  ~Field() = default;

  /// Whether this Field holds a handle (false when empty or moved from).
  explicit operator bool() const noexcept { return shared_ != nullptr; }

  /// pheromone_wait_frame's status, nothing thrown: PHEROMONE_STATUS_OK (a newer frame),
  /// _TIMEOUT, _INTERRUPTED (a signal the program handles cut the wait short), _BORROWED (a
  /// Frame of this Field lives), or a failure (pheromone_last_error() says why).
  PheromoneStatus try_wait_frame(std::chrono::nanoseconds timeout,
                                 PheromoneWaitPolicy policy = Wait::event()) noexcept {
    return pheromone_wait_frame(handle(), policy, static_cast<uint64_t>(timeout.count()));
  }

  /// Borrows the newest frame into `out` until `out` is destroyed or reassigned:
  /// PHEROMONE_STATUS_BORROWED while another Frame of this Field lives.
  PheromoneStatus try_borrow(Frame& out) noexcept {
    if (shared_ && shared_->borrowed) return PHEROMONE_STATUS_BORROWED;
    out = Frame();
    PheromoneFrameView view;
    PheromoneStatus s = pheromone_frame_borrow(handle(), &view);
    if (s != PHEROMONE_STATUS_OK) return s;
    shared_->borrowed = true;
    out = Frame(shared_, view);
    return PHEROMONE_STATUS_OK;
  }

  PheromoneStatus try_deposit(const PheromoneDeposit& d) noexcept {
    return pheromone_deposit(handle(), &d);
  }

  /// pheromone_deposit_confirmed: OK (applied or forwarded, `r` filled), _REJECTED (`r.reason`),
  /// _TIMEOUT, _INTERRUPTED, …
  PheromoneStatus try_deposit_confirmed(const PheromoneDeposit& d,
                                        std::chrono::nanoseconds timeout,
                                        PheromoneReceipt& r) noexcept {
    return pheromone_deposit_confirmed(handle(), &d, static_cast<uint64_t>(timeout.count()), &r);
  }

  PheromoneStatus try_deposit_pose(
      const PheromonePoseEstimate& pose,
      const PheromoneEllipseParams& params = default_ellipse_params()) noexcept {
    return pheromone_deposit_pose(handle(), &pose, &params);
  }

  /// pheromone_field_fd: the descriptor to poll for frames (valid while this Field lives).
  PheromoneStatus try_fd(int& fd) const noexcept { return pheromone_field_fd(handle(), &fd); }

#if PHEROMONE_HPP_EXCEPTIONS
  /// Waits up to `timeout` for a newer frame; false if none came. A signal the program handles
  /// that cuts the wait short throws Error with PHEROMONE_STATUS_INTERRUPTED (the program's
  /// handler ran); so does a wait while a Frame of this Field lives, with _BORROWED.
  bool wait_frame(std::chrono::nanoseconds timeout, PheromoneWaitPolicy policy = Wait::event()) {
    PheromoneStatus s = try_wait_frame(timeout, policy);
    if (s == PHEROMONE_STATUS_TIMEOUT) return false;
    check(s);
    return true;
  }

  /// Borrows the newest frame until the returned Frame is destroyed; throws Error
  /// (PHEROMONE_STATUS_BORROWED) while another Frame of this Field lives.
  Frame borrow() {
    if (shared_ && shared_->borrowed) {
      throw Error(PHEROMONE_STATUS_BORROWED,
                  "a Frame of this Field is alive: destroy it before borrowing again");
    }
    Frame f;
    check(try_borrow(f));
    return f;
  }

  void deposit(const PheromoneDeposit& d) { check(try_deposit(d)); }

  /// Sends a deposit and waits up to `timeout` for the field's receipt (applied in frame N, or
  /// forwarded by a mirror). Throws `Error` with PHEROMONE_STATUS_REJECTED when the field refused
  /// it, and PHEROMONE_STATUS_TIMEOUT (or _INTERRUPTED) when no receipt came (it may still be
  /// applied, once).
  PheromoneReceipt deposit_confirmed(const PheromoneDeposit& d, std::chrono::nanoseconds timeout) {
    PheromoneReceipt r{};
    check(try_deposit_confirmed(d, timeout, r));
    return r;
  }

  /// Seed 000's uncertainty-aware ellipse deposit for a pose estimate.
  void deposit_pose(const PheromonePoseEstimate& pose,
                    const PheromoneEllipseParams& params = default_ellipse_params()) {
    check(try_deposit_pose(pose, params));
  }

  /// The descriptor to poll for frames (pheromone_field_fd).
  int fd() const {
    int fd = -1;
    check(try_fd(fd));
    return fd;
  }
#endif

  PheromoneField* get() const noexcept { return handle(); }

 private:
  explicit Field(PheromoneField* h) noexcept {
    // Allocation failure: the handle is detached and the Field stays empty (with
    // -fno-exceptions, operator new's failure ends the program instead).
#if PHEROMONE_HPP_EXCEPTIONS
    try {
      shared_ = std::make_shared<detail::Shared>();
    } catch (...) {
      pheromone_field_detach(h);
      return;
    }
#else
    shared_ = std::make_shared<detail::Shared>();
#endif
    shared_->handle = h;
  }
  PheromoneField* handle() const noexcept { return shared_ ? shared_->handle : nullptr; }

  std::shared_ptr<detail::Shared> shared_;
};

}  // namespace pheromone

#endif  // PHEROMONE_HPP
