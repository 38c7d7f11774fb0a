build2/obj/common/scene/motion.o: common/scene/motion.c \
 common/scene/motion.h common/base/vec.h
common/scene/motion.h:
common/base/vec.h:
