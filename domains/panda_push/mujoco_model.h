#pragma once
// MuJoCo plumbing of the panda-push plug-in (internal: includes MuJoCo's headers, which the
// plug-in's public headers do not): owning handles for mjModel and mjData, the embedded model
// file, and MuJoCo's error and warning handlers turned into secure::Error.
#include <mujoco/mujoco.h>

#include <memory>
#include <string>

namespace secure::domains::panda_push {

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

/// The task's model (panda_push.xml, embedded at build time), parsed once per process.
const mjModel* PandaPushModel();

/// Installs handlers (once per process) so that mju_error throws secure::Error instead of
/// exiting (MuJoCo's default waits for Enter, then exits), and mju_warning is recorded: any
/// warning MuJoCo prints while a model loads makes the load fail.
void InstallMujocoHandlers();

}  // namespace secure::domains::panda_push
