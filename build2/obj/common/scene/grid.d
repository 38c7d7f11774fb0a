build2/obj/common/scene/grid.o: common/scene/grid.c common/scene/grid.h \
 common/scene/medium.h common/scene/scene_limits.h common/base/vec.h \
 common/base/bytes.h common/base/log.h common/scene/motion.h \
 common/base/rng.h
common/scene/grid.h:
common/scene/medium.h:
common/scene/scene_limits.h:
common/base/vec.h:
common/base/bytes.h:
common/base/log.h:
common/scene/motion.h:
common/base/rng.h:
