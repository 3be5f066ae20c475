// The device's mount on the fixture and the check that it sits as configured (issue 38;
// daemon/station/device_pipeline.h, core/analysis/mount_check.h).
#include <fmt/format.h>

#include "core/frames/mount.h"
#include "daemon/station/device_pipeline.h"

namespace turncal::daemon {

bool DevicePipeline::CheckMountWith(const PoseRecord& record) {
  if (!record.acc || record.pose.is_rate()) return false;
  const bool was_wrong = mount_check.wrong;
  const bool was_determined = mount_check.determined;
  const Mat3<double> was = mount_check.rotation;
  MountObservation o;
  o.predicted_case =
      PredictedGravityDirection(context.mounting, record.pose.C_p_q(), context.reference.g_ned);
  o.measured = record.acc->mean;
  mount_observations.push_back(o);
  mount_check = CheckMount(mount_observations);
  const bool changed = was_wrong != mount_check.wrong || was_determined != mount_check.determined ||
                       !was.isApprox(mount_check.rotation);
  if (changed) mount_wrong_published = false;
  return changed;
}

std::string DevicePipeline::MountProblem() const {
  if (!mount_check.wrong) return "";
  const std::string who = slot.empty() ? "the unit" : "slot " + slot;
  if (!mount_check.determined) {
    return fmt::format(
        "{} does not sit as its mount says: gravity is {:.0f} deg from where the mount puts it "
        "(one direction so far; which rotation it is shows at a pose with gravity along another "
        "of its axes). Check the unit and its [[device]] {}; the poses are kept",
        who, mount_check.largest_off_deg, slot.empty() ? "mount" : "slot");
  }
  const Mat3<double> observed = mount_check.rotation * context.mounting;
  return fmt::format(
      "{} looks {} (over {} poses, {:.1f} deg RMS misfit): its mount would be {}. Turn the unit "
      "back, or set [[device]] mount = {} (or put it in the slot that has that mount) and "
      "reload: the poses already captured are used again (the state directory's journal)",
      who, DescribeMountRotation(mount_check.rotation), mount_check.poses, mount_check.misfit_deg,
      MountConfigText(observed), MountConfigText(observed));
}

nlohmann::json DevicePipeline::MountJson() const {
  nlohmann::json check = {{"poses", mount_check.poses},
                          {"determined", mount_check.determined},
                          {"ok", !mount_check.wrong},
                          {"misfit_deg", mount_check.misfit_deg}};
  if (mount_check.determined) {
    check["rotation_deg"] = mount_check.angle_deg;
    check["rotation"] = DescribeMountRotation(mount_check.rotation);
    check["observed_mount"] = MountConfigText(mount_check.rotation * context.mounting);
  }
  if (mount_check.wrong) check["problem"] = MountProblem();
  return {{"configured", mount_configured},
          {"slot", slot.empty() ? nlohmann::json() : nlohmann::json(slot)},
          {"mount", MountConfigText(context.mounting)},
          {"check", check}};
}

}  // namespace turncal::daemon
