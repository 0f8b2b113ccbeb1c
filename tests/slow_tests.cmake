# The `slow` label: tests that train whole quick experiments or full-size models, tens of seconds
# each. `make test` leaves them out and `make test-slow` runs them; CI runs them every time
# (.ci/run: make test-ci). Read by CTest (a TEST_INCLUDE_FILES entry of tests/CMakeLists.txt,
# after the discovered GoogleTest cases), so that single cases of an executable can carry it.
# Each entry: the case's module label, then its CTest name. A name that matches no test is an
# error of the test `slow_tests_exist`, so the list cannot go stale silently.
set(SECURE_SLOW_TESTS
  accuracy   AccuracyTest.PandaHeldOutBalancedAccuracy
  accuracy   AccuracyTest.Table1MeetsTheTargetsOnTheDefaultObstacle
  experiments ShardedPipelineTest.ShardsMergeToTheUnshardedResultAndTaskFilesAreReused
  experiments ShardTest.TwoShardsInOneDirectoryMergeToTheUnshardedResult
  experiments ShardTest.SlurmArrayElementsInTheirOwnDirectoriesMergeToTheUnshardedResult
  experiments ShardTest.MpirunRanksMergeToTheUnshardedResult
  experiments ShardTest.BadShardValuesAreOneLineErrors
  experiments ReproduceTest.ShardsThenAnUnshardedRunGiveTheExperimentsResult
  experiments ReproduceTest.QuickProfileRunsEveryStudyAndTheReportShowsEveryTable
  experiments ShardTest.MergeNamesMissingDuplicateAndForeignTasks
  experiments PipelineTest.RunsEveryMethodOverSeedsAndDoesNotDependOnTheWorkerCount
  experiments UserStudy.QuickRunIsDeterministicAndIndependentOfThreads
  experiments DerbyExperimentsTest.Table3RunsBcAirlSecureAndDoesNotDependOnTheWorkerCount
  experiments DerbyExperimentsTest.AblationAndJointExperimentsRunTheirMethods
  apps       FaultInjectionTest.KilledBarrierTrainingRerunsToTheSameModel
  apps       FaultInjectionTest.KilledAirlTrainingResumesToTheSameModel
  apps       FaultInjectionTest.KilledExperimentRerunsToTheSameArtefacts
  apps       CliTest.ProgressLineOnlyWhenAskedAndOutputOtherwiseUnchanged
  apps       CliTest.CompareTwoShieldSettingsOnTheSameEpisodes
  apps       CliTest.KitchenCuttingRunsTheMethodComparisonAndItsLabelCheck
  apps       CliTest.UserStudyQuickPrintsTheConditionsBesideThePapersRatings
  apps       CliTest.DemoQuickPrintsTheResultDocument
  apps       CliQueryTest.LabelEfficiencyQuickIsDeterministicResumesAndMergesShards
  apps       CliQueryTest.LabelEfficiencyDerbyClosedLoopOnARunsPolicies
)
if(NOT SECURE_SLOW_TESTS_LIST_ONLY)
  list(LENGTH SECURE_SLOW_TESTS _n)
  math(EXPR _last "${_n} - 1")
  foreach(_i RANGE 0 ${_last} 2)
    math(EXPR _j "${_i} + 1")
    list(GET SECURE_SLOW_TESTS ${_i} _label)
    list(GET SECURE_SLOW_TESTS ${_j} _name)
    # A name the build did not define (e.g. the sanitizer build leaves the experiments out) is
    # ignored by CTest here; slow_tests_exist checks the Release build's list.
    set_tests_properties(${_name} PROPERTIES LABELS "${_label};slow")
  endforeach()
endif()
