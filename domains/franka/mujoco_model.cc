#include "domains/franka/mujoco_model.h"

#include <cstring>
#include <mutex>
#include <vector>

#include "secure/common/error.h"

namespace secure::domains::franka {

namespace {

thread_local std::string* warning_sink = nullptr;

void ThrowMujocoError(const char* message) { SECURE_THROW("MuJoCo error: " << message); }

void RecordMujocoWarning(const char* message) {
  if (warning_sink != nullptr) {
    if (!warning_sink->empty()) *warning_sink += "; ";
    *warning_sink += message;
  }
}

}  // namespace

void InstallMujocoHandlers() {
  static std::once_flag once;
  std::call_once(once, [] {
    mju_user_error = ThrowMujocoError;
    mju_user_warning = RecordMujocoWarning;
  });
}

MujocoModel MujocoModel::FromXml(const std::string& xml, const std::string& name) {
  InstallMujocoHandlers();
  // The text goes through MuJoCo's virtual file system (no file on disk).
  auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  struct VfsGuard {
    mjVFS* v;
    ~VfsGuard() { mj_deleteVFS(v); }
  } guard{vfs.get()};
  const std::string file = "model.xml";
  SECURE_CHECK(mj_makeEmptyFileVFS(vfs.get(), file.c_str(), static_cast<int>(xml.size())) == 0,
               name << ": MuJoCo's virtual file system refused the model");
  const int index = mj_findFileVFS(vfs.get(), file.c_str());
  SECURE_CHECK(index >= 0, name << ": model not found in MuJoCo's virtual file system");
  std::memcpy(vfs->filedata[index], xml.data(), xml.size());
  std::string warnings;
  warning_sink = &warnings;
  char error[1024] = {0};
  mjModel* model = mj_loadXML(file.c_str(), vfs.get(), error, sizeof(error));
  warning_sink = nullptr;
  MujocoModel result;
  result.model_.reset(model);
  SECURE_CHECK(model != nullptr, name << ": MuJoCo cannot load the model: " << error);
  SECURE_CHECK(error[0] == 0, name << ": MuJoCo warns while loading the model: " << error);
  SECURE_CHECK(warnings.empty(), name << ": MuJoCo warns while loading the model: " << warnings);
  return result;
}

MujocoModel MujocoModel::Copy(const mjModel* model) {
  InstallMujocoHandlers();
  MujocoModel result;
  result.model_.reset(mj_copyModel(nullptr, model));
  SECURE_CHECK(result.model_ != nullptr, "MuJoCo cannot copy a model");
  return result;
}

MujocoData::MujocoData(const MujocoModel& model) : data_(mj_makeData(model.get())) {
  SECURE_CHECK(data_ != nullptr, "MuJoCo cannot allocate data for a model");
}

void CheckWarnings(const mjData* d, const char* who, const char* where) {
  for (int i = 0; i < mjNWARNING; ++i) {
    SECURE_CHECK(d->warning[i].number == 0, who << ": MuJoCo warning during " << where << ": "
                                                << mju_warningText(i, d->warning[i].lastinfo));
  }
}

}  // namespace secure::domains::franka
