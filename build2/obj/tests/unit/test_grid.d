build2/obj/tests/unit/test_grid.o: tests/unit/test_grid.c \
 common/base/log.h common/base/rng.h common/scene/grid.h \
 common/scene/medium.h common/scene/scene_limits.h common/base/vec.h
common/base/log.h:
common/base/rng.h:
common/scene/grid.h:
common/scene/medium.h:
common/scene/scene_limits.h:
common/base/vec.h:
