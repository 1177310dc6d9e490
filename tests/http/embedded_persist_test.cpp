// An EmbeddedSession on a data directory (ServiceOptions::data_dir): what one session stored, the
// next one on the same directory has, with the same ids and values.
#include <gtest/gtest.h>

#include "http_test_support.h"
#include "softshell/embedded_session.h"
#include "temp_dir.h"

namespace softshell {
namespace {

using namespace test;

TEST(EmbeddedPersistTest, ASessionOnADataDirectoryRestoresTheLastOnesWorld) {
  const TempDir dir("softshell-embedded");
  service::ServiceOptions options = test_service_options();
  options.data_dir = dir.path;
  GeomId id;
  std::vector<DeformationResult> before;
  {
    EmbeddedSession session(options);
    id = session.upload(exact_grid(), exact_material(), "embedded").value().id;
    for (int k = 1; k <= 3; ++k) before.push_back(session.deform(id, pinned_push(k)).value());
    // The directory is the session's while it lives.
    EXPECT_THROW(EmbeddedSession{options}, Exception);
  }
  {
    EmbeddedSession session(options);
    ASSERT_EQ(session.result_ids(id).value().size(), 3u);
    for (const DeformationResult& r : before) {
      const DeformationResult now = session.result(id, r.res_id).value();
      EXPECT_EQ(now.positions, r.positions);
      EXPECT_EQ(wire::encode_request_json(session.result_request(id, r.res_id).value()),
                wire::encode_request_json(pinned_push(static_cast<int>(r.res_id))));
    }
    EXPECT_EQ(session.deform(id, pinned_push(4)).value().res_id, 4u);
  }
}

}  // namespace
}  // namespace softshell
