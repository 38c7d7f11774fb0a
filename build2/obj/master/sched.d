build2/obj/master/sched.o: master/sched.c master/sched.h \
 common/base/log.h
master/sched.h:
common/base/log.h:
