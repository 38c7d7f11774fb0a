build2/obj/tests/unit/test_journal.o: tests/unit/test_journal.c \
 master/journal.h common/wire/blob.h common/render/tile.h \
 common/image/imgio.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h
master/journal.h:
common/wire/blob.h:
common/render/tile.h:
common/image/imgio.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
