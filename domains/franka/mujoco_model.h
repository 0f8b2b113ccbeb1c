#pragma once
// MuJoCo plumbing shared by the Franka plug-ins (panda-push, kitchen-cutting): owning handles for
// mjModel and mjData, MuJoCo's error and warning handlers turned into secure::Error, and the
// per-step warning check. Internal to the plug-ins' sources: it includes MuJoCo's headers, which
// the plug-ins' public headers do not.
#include <mujoco/mujoco.h>

#include <memory>
#include <string>

namespace secure::domains::franka {

/// An owned mjModel (mj_deleteModel on destruction).
class MujocoModel {
 public:
  /// Parses MJCF text (named `name` in messages). @throws secure::Error with MuJoCo's message
  /// on a parse error, and on any warning MuJoCo prints while compiling the model.
  static MujocoModel FromXml(const std::string& xml, const std::string& name);
  /// A copy (mj_copyModel).
  static MujocoModel Copy(const mjModel* model);

  mjModel* get() const { return model_.get(); }

 private:
  struct Delete {
    void operator()(mjModel* m) const { mj_deleteModel(m); }
  };
  std::unique_ptr<mjModel, Delete> model_;
};

/// An owned mjData for a model.
class MujocoData {
 public:
  explicit MujocoData(const MujocoModel& model);
  mjData* get() const { return data_.get(); }

 private:
  struct Delete {
    void operator()(mjData* d) const { mj_deleteData(d); }
  };
  std::unique_ptr<mjData, Delete> data_;
};

/// Installs handlers (once per process) so that mju_error throws secure::Error instead of
/// exiting (MuJoCo's default waits for Enter, then exits), and mju_warning is recorded: any
/// warning MuJoCo prints while a model loads makes the load fail.
void InstallMujocoHandlers();

/// @throws secure::Error "<who>: MuJoCo warning during <where>: <MuJoCo's text>" if any of
/// MuJoCo's warning counters in `d` is non-zero (e.g. the contact buffer overflowed).
void CheckWarnings(const mjData* d, const char* who, const char* where);

}  // namespace secure::domains::franka
