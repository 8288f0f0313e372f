// The shim's C entry points: the Rust side (src/ffi.rs) loads the shim's
// shared library when a DART world is first made and looks these up by
// name.
//
// Conventions, the same for every entry point:
// - a sequence crosses as a pointer and a length, text as UTF-8 bytes and
//   a length;
// - an entry point that can fail returns NULL on success, or the C++
//   exception's message as a string from malloc, which the caller frees
//   with rgdart_free; results go through pointers (rgdart_take_messages,
//   which cannot fail, returns its text the same way, NULL for none);
// - nothing is thrown out of an entry point (noexcept: what escapes ends
//   the process, as it did through cxx).

#include "dart_shim.h"

#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>

#define RGDART_API extern "C"

namespace {

using rgdart::Slice;

char* copy(const std::string& s) noexcept
{
  char* out = static_cast<char*>(std::malloc(s.size() + 1));
  // NULL means success to the caller: out of memory ends the process.
  if (!out)
    std::abort();
  std::memcpy(out, s.c_str(), s.size() + 1);
  return out;
}

// Runs `f`; what it throws becomes the returned message.
template <typename F>
char* call(F&& f)
{
  try
  {
    f();
    return nullptr;
  }
  catch (const std::exception& e)
  {
    return copy(e.what());
  }
  catch (...)
  {
    return copy("an unknown C++ exception");
  }
}

Slice<const double> in(const double* p, std::size_t n)
{
  return Slice<const double>(p, n);
}

Slice<double> out(double* p, std::size_t n)
{
  return Slice<double>(p, n);
}

std::string_view text(const char* p, std::size_t n)
{
  return std::string_view(p, n);
}

rgdart::World* world(void* w)
{
  return static_cast<rgdart::World*>(w);
}

const rgdart::World* world(const void* w)
{
  return static_cast<const rgdart::World*>(w);
}

} // namespace

RGDART_API void rgdart_free(char* s) noexcept
{
  std::free(s);
}

RGDART_API char* rgdart_take_messages() noexcept
{
  // NULL when DART said nothing: no allocation for the usual case.
  std::string said = rgdart::take_messages();
  return said.empty() ? nullptr : copy(said);
}

RGDART_API void rgdart_say(const char* p, std::size_t n) noexcept
{
  rgdart::say(text(p, n));
}

RGDART_API char* rgdart_new_world(
    double timestep_s,
    const double* gravity,
    std::size_t gravity_n,
    const char* detector,
    std::size_t detector_n,
    const char* lcp,
    std::size_t lcp_n,
    void** created) noexcept
{
  return call([&] {
    *created = rgdart::new_world(
                   timestep_s,
                   in(gravity, gravity_n),
                   text(detector, detector_n),
                   text(lcp, lcp_n))
                   .release();
  });
}

RGDART_API void rgdart_delete_world(void* w) noexcept
{
  delete world(w);
}

RGDART_API char* rgdart_add_robot_body(
    void* w,
    const char* name,
    std::size_t name_n,
    std::int64_t parent,
    std::uint8_t kind,
    const double* joint_pose,
    std::size_t joint_pose_n,
    const double* axis,
    std::size_t axis_n,
    double mass_kg,
    const double* com,
    std::size_t com_n,
    const double* inertia,
    std::size_t inertia_n,
    std::size_t* body) noexcept
{
  return call([&] {
    *body = world(w)->add_robot_body(
        text(name, name_n),
        parent,
        kind,
        in(joint_pose, joint_pose_n),
        in(axis, axis_n),
        mass_kg,
        in(com, com_n),
        in(inertia, inertia_n));
  });
}

RGDART_API char* rgdart_set_joint_limits(
    void* w, std::size_t joint, double lower, double upper) noexcept
{
  return call([&] { world(w)->set_joint_limits(joint, lower, upper); });
}

RGDART_API char* rgdart_set_joint_friction(
    void* w, std::size_t joint, double friction) noexcept
{
  return call([&] { world(w)->set_joint_friction(joint, friction); });
}

RGDART_API char* rgdart_set_actuator(
    void* w, std::size_t joint, bool servo, double limit) noexcept
{
  return call([&] { world(w)->set_actuator(joint, servo, limit); });
}

RGDART_API char* rgdart_set_drives(
    void* w,
    const double* command,
    std::size_t command_n,
    const double* damping,
    std::size_t damping_n,
    const double* stiffness,
    std::size_t stiffness_n,
    const double* rest,
    std::size_t rest_n) noexcept
{
  return call([&] {
    world(w)->set_drives(
        in(command, command_n),
        in(damping, damping_n),
        in(stiffness, stiffness_n),
        in(rest, rest_n));
  });
}

RGDART_API char* rgdart_add_shape(
    void* w,
    bool object,
    std::size_t body,
    std::uint8_t kind,
    const double* dims,
    std::size_t dims_n,
    const double* pose,
    std::size_t pose_n,
    double friction,
    double restitution) noexcept
{
  return call([&] {
    world(w)->add_shape(
        object,
        body,
        kind,
        in(dims, dims_n),
        in(pose, pose_n),
        friction,
        restitution);
  });
}

RGDART_API char* rgdart_add_mesh(
    void* w,
    std::size_t body,
    const double* vertices,
    std::size_t vertices_n,
    const std::uint32_t* indices,
    std::size_t indices_n,
    const double* pose,
    std::size_t pose_n,
    double friction) noexcept
{
  return call([&] {
    world(w)->add_mesh(
        body,
        in(vertices, vertices_n),
        Slice<const std::uint32_t>(indices, indices_n),
        in(pose, pose_n),
        friction);
  });
}

RGDART_API char* rgdart_add_object(
    void* w,
    const char* name,
    std::size_t name_n,
    double mass_kg,
    const double* inertia,
    std::size_t inertia_n,
    const double* pose,
    std::size_t pose_n,
    std::size_t* object) noexcept
{
  return call([&] {
    *object = world(w)->add_object(
        text(name, name_n), mass_kg, in(inertia, inertia_n), in(pose, pose_n));
  });
}

RGDART_API char* rgdart_add_ground(
    void* w, double height, double friction, double restitution) noexcept
{
  return call([&] { world(w)->add_ground(height, friction, restitution); });
}

RGDART_API char* rgdart_finish(void* w) noexcept
{
  return call([&] { world(w)->finish(); });
}

RGDART_API char* rgdart_step(void* w) noexcept
{
  return call([&] { world(w)->step(); });
}

RGDART_API char* rgdart_advance(
    void* w,
    const double* command,
    std::size_t command_n,
    const double* damping,
    std::size_t damping_n,
    const double* stiffness,
    std::size_t stiffness_n,
    const double* rest,
    std::size_t rest_n,
    double* positions,
    std::size_t positions_n,
    double* velocities,
    std::size_t velocities_n,
    rgdart::StepReport* report) noexcept
{
  return call([&] {
    *report = world(w)->advance(
        in(command, command_n),
        in(damping, damping_n),
        in(stiffness, stiffness_n),
        in(rest, rest_n),
        out(positions, positions_n),
        out(velocities, velocities_n));
  });
}

RGDART_API char* rgdart_step_raw(void* w, std::uint64_t n) noexcept
{
  return call([&] { world(w)->step_raw(n); });
}

RGDART_API void rgdart_joint_state(
    const void* w,
    double* positions,
    std::size_t positions_n,
    double* velocities,
    std::size_t velocities_n) noexcept
{
  world(w)->joint_state(
      out(positions, positions_n), out(velocities, velocities_n));
}

RGDART_API char* rgdart_set_joint_state(
    void* w,
    const double* positions,
    std::size_t positions_n,
    const double* velocities,
    std::size_t velocities_n) noexcept
{
  return call([&] {
    world(w)->set_joint_state(
        in(positions, positions_n), in(velocities, velocities_n));
  });
}

RGDART_API void rgdart_body_pose(
    const void* w, std::size_t body, double* pose, std::size_t n) noexcept
{
  world(w)->body_pose(body, out(pose, n));
}

RGDART_API void rgdart_object_state(
    const void* w, std::size_t i, double* state, std::size_t n) noexcept
{
  world(w)->object_state(i, out(state, n));
}

RGDART_API char* rgdart_set_object_state(
    void* w, std::size_t i, const double* state, std::size_t n) noexcept
{
  return call([&] { world(w)->set_object_state(i, in(state, n)); });
}

RGDART_API void rgdart_object_coordinates(
    const void* w, std::size_t i, double* values, std::size_t n) noexcept
{
  world(w)->object_coordinates(i, out(values, n));
}

RGDART_API char* rgdart_set_object_coordinates(
    void* w, std::size_t i, const double* values, std::size_t n) noexcept
{
  return call([&] { world(w)->set_object_coordinates(i, in(values, n)); });
}

RGDART_API void rgdart_set_time(void* w, double t_s) noexcept
{
  world(w)->set_time(t_s);
}

RGDART_API std::size_t rgdart_contact_count(const void* w) noexcept
{
  return world(w)->contact_count();
}
