build2/obj/tests/unit/test_proto.o: tests/unit/test_proto.c \
 common/wire/proto.h common/wire/blob.h common/render/tile.h \
 common/image/imgio.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h
common/wire/proto.h:
common/wire/blob.h:
common/render/tile.h:
common/image/imgio.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
